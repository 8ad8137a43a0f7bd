//! Small wgpu helpers shared by the passes: bind-group-layout entries, buffer creation,
//! texture creation and the full-texture view. Nothing here holds state.

use wgpu::util::DeviceExt;

/// A `texture_2d<f32>` read with `textureLoad` only (no sampler, so RGBA32F works without
/// `FLOAT32_FILTERABLE`).
pub fn texture_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// How a shader reads a texture texel by texel (`textureLoad`, no sampler).
///
/// [`TexelReads::Sampled`] binds a `texture_2d` and works on every adapter;
/// [`TexelReads::Storage`] binds a read-only `texture_storage_2d` of the texture's exact
/// format (adapters with [`crate::gpu::Gpu::supports_storage_reads`]; the texture needs
/// [`TexelReads::usage`]). Both read the same values bit for bit. On lavapipe the storage read
/// is much the cheaper (llvmpipe's image load skips the sampler's level-of-detail and
/// format-conversion code; measured in `docs/render.md`). The shader does not declare the
/// texture itself: the host prepends [`TexelReads::wgsl`], which declares it and defines
/// `load_NAME(t: vec2<i32>) -> vec4<f32 | u32>`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TexelReads {
    /// `texture_2d<f32 | u32>`, `textureLoad(tex, t, 0)`.
    #[default]
    Sampled,
    /// `texture_storage_2d<FORMAT, read>`, `textureLoad(tex, t)`.
    Storage,
}

impl TexelReads {
    /// The bind-group-layout entry of a texture of `format` (RGBA32F or RGBA32Uint) read this way.
    pub fn entry(
        self,
        binding: u32,
        visibility: wgpu::ShaderStages,
        format: wgpu::TextureFormat,
    ) -> wgpu::BindGroupLayoutEntry {
        let ty = match self {
            Self::Sampled => wgpu::BindingType::Texture {
                sample_type: match format {
                    wgpu::TextureFormat::Rgba32Uint => wgpu::TextureSampleType::Uint,
                    _ => wgpu::TextureSampleType::Float { filterable: false },
                },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            Self::Storage => wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::ReadOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
        };
        wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty,
            count: None,
        }
    }

    /// The usage a texture read this way needs.
    pub fn usage(self) -> wgpu::TextureUsages {
        match self {
            Self::Sampled => wgpu::TextureUsages::TEXTURE_BINDING,
            Self::Storage => wgpu::TextureUsages::STORAGE_BINDING,
        }
    }

    /// WGSL declaring `name` at `@group(group) @binding(binding)` (a texture of `format`:
    /// RGBA32F or RGBA32Uint) and defining `fn load_NAME(t: vec2<i32>)` returning its texel `t`.
    pub fn wgsl(self, group: u32, binding: u32, name: &str, format: wgpu::TextureFormat) -> String {
        let (scalar, storage_format) = match format {
            wgpu::TextureFormat::Rgba32Uint => ("u32", "rgba32uint"),
            _ => ("f32", "rgba32float"),
        };
        let (ty, level) = match self {
            Self::Sampled => (format!("texture_2d<{scalar}>"), ", 0"),
            Self::Storage => (format!("texture_storage_2d<{storage_format}, read>"), ""),
        };
        format!(
            "@group({group}) @binding({binding}) var {name}: {ty};\n\
             fn load_{name}(t: vec2<i32>) -> vec4<{scalar}> {{ return textureLoad({name}, t{level}); }}\n"
        )
    }
}

/// The shadow maps' layout entry (`shadow_maps` in shaders/shadow.wgsl: a depth 2D array),
/// shared by the first-order pass and the per-pixel direct light of the display.
pub fn shadow_maps_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Depth,
            view_dimension: wgpu::TextureViewDimension::D2Array,
            multisampled: false,
        },
        count: None,
    }
}

/// The shadow maps' comparison sampler entry (`shadow_sampler` in shaders/shadow.wgsl).
pub fn shadow_sampler_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
        count: None,
    }
}

/// A uniform buffer.
pub fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A storage buffer, read-only or read-write.
pub fn storage_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    read_only: bool,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A write-only 2D storage texture of `format`.
pub fn storage_texture_entry(
    binding: u32,
    format: wgpu::TextureFormat,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension: wgpu::TextureViewDimension::D2,
        },
        count: None,
    }
}

/// A buffer initialised with `contents`.
pub fn buffer_init(
    device: &wgpu::Device,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage,
    })
}

/// A 2D single-mip texture.
pub fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// The default view of a texture.
pub fn view(tex: &wgpu::Texture) -> wgpu::TextureView {
    tex.create_view(&wgpu::TextureViewDescriptor::default())
}

/// A WGSL shader module.
pub fn shader(device: &wgpu::Device, label: &str, source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    })
}

/// Additive blending (`One + One`) of colour and alpha: how the transfer pieces accumulate.
pub const ADDITIVE: wgpu::BlendState = wgpu::BlendState {
    color: wgpu::BlendComponent {
        src_factor: wgpu::BlendFactor::One,
        dst_factor: wgpu::BlendFactor::One,
        operation: wgpu::BlendOperation::Add,
    },
    alpha: wgpu::BlendComponent {
        src_factor: wgpu::BlendFactor::One,
        dst_factor: wgpu::BlendFactor::One,
        operation: wgpu::BlendOperation::Add,
    },
};

/// A render pipeline with no depth, no culling and one colour target of `format` (blended by
/// `blend`, or written when `None`): vertex entry `vs` with vertex `buffers`, fragment entry `fs`,
/// both from `module`. What the lightmap-space passes (full-screen triangles, instanced quads)
/// share; `layout` `None` lets wgpu derive it from the shader.
#[allow(
    clippy::too_many_arguments,
    reason = "a pipeline descriptor's independent parts; a struct would only rename them"
)]
pub fn colour_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: Option<&wgpu::PipelineLayout>,
    module: &wgpu::ShaderModule,
    (vs, buffers): (&str, &[Option<wgpu::VertexBufferLayout>]),
    fs: &str,
    format: wgpu::TextureFormat,
    blend: Option<wgpu::BlendState>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout,
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vs),
            compilation_options: Default::default(),
            buffers,
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fs),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// `shaders/fullscreen.wgsl`: the `vs_fullscreen` vertex shader (one triangle covering the
/// target), prepended to every shader that draws with [`fullscreen_pipeline`].
pub const FULLSCREEN_WGSL: &str = include_str!("../shaders/fullscreen.wgsl");

/// [`colour_pipeline`] for a full-screen triangle drawn by `vs_fullscreen` (the module's
/// source must include [`FULLSCREEN_WGSL`]).
pub fn fullscreen_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: Option<&wgpu::PipelineLayout>,
    module: &wgpu::ShaderModule,
    fs: &str,
    format: wgpu::TextureFormat,
    blend: Option<wgpu::BlendState>,
) -> wgpu::RenderPipeline {
    colour_pipeline(
        device,
        label,
        layout,
        module,
        ("vs_fullscreen", &[]),
        fs,
        format,
        blend,
    )
}

/// A colour attachment of `view` cleared to transparent (0, 0, 0, 0) and stored.
pub fn cleared_attachment(view: &wgpu::TextureView) -> Option<wgpu::RenderPassColorAttachment<'_>> {
    Some(wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
            store: wgpu::StoreOp::Store,
        },
    })
}

/// A render pass over one colour `view`, cleared to transparent black, no depth: how every
/// lightmap-space pass starts.
pub fn clear_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    view: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[cleared_attachment(view)],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}
