//! JSON index files that carry a `format` name and a `version` number beside their body
//! (`index.json`, `atlases.json`): written with both fields first, read by checking both before
//! the body is parsed, so a file of another kind or version is named as such, not as a schema
//! error.

use serde::Serialize;

/// Pretty JSON of `body` with the fields `format` and `version` first, newline-terminated.
///
/// # Errors
/// The serialiser's error.
pub fn to_versioned_json<T: Serialize>(
    format: &'static str,
    version: u32,
    body: &T,
) -> serde_json::Result<String> {
    #[derive(Serialize)]
    struct Wire<'a, T> {
        format: &'static str,
        version: u32,
        #[serde(flatten)]
        body: &'a T,
    }
    let mut text = serde_json::to_string_pretty(&Wire {
        format,
        version,
        body,
    })?;
    text.push('\n');
    Ok(text)
}

/// Why [`from_versioned_json`] refused a file.
#[derive(Debug)]
pub enum VersionedError {
    /// Not JSON, or the body does not match the schema.
    Json(serde_json::Error),
    /// The top level is not a JSON object.
    NotObject,
    /// `format` is missing or another name; the value found (as JSON, or `<missing>`).
    Format(String),
    /// `version` is missing or another number; the value found (as JSON, or `<missing>`).
    Version(String),
}

/// Parses `text` as a JSON object whose `format` is `format` and whose `version` is `version`
/// (checked in that order, before the body), then the rest as `T`.
///
/// # Errors
/// [`VersionedError`] saying which check failed.
pub fn from_versioned_json<T: serde::de::DeserializeOwned>(
    text: &[u8],
    format: &str,
    version: u32,
) -> Result<T, VersionedError> {
    let found =
        |v: Option<serde_json::Value>| v.map_or_else(|| "<missing>".into(), |v| v.to_string());
    let mut value: serde_json::Value =
        serde_json::from_slice(text).map_err(VersionedError::Json)?;
    let obj = value.as_object_mut().ok_or(VersionedError::NotObject)?;
    match obj.remove("format") {
        Some(serde_json::Value::String(f)) if f == format => {}
        other => return Err(VersionedError::Format(found(other))),
    }
    match obj.remove("version") {
        Some(v) if v.as_u64() == Some(u64::from(version)) => {}
        other => return Err(VersionedError::Version(found(other))),
    }
    serde_json::from_value(value).map_err(VersionedError::Json)
}
