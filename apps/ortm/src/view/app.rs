//! The viewer's state and egui user interface: lights panel, view and debug choices,
//! exposure, the number of transfer maps, stats, help overlay; mouse and keyboard handling of
//! the 3D view (orbit, pan, zoom, light dragging). No GPU calls here: the UI records what
//! changed and [`super::window`] acts on it.

use std::path::PathBuf;

use egui::{Color32, Key, Pos2, Rect, Sense, Stroke, Vec2};
use glam::Vec3;
use ortm::scene::Light;

use super::camera::OrbitCamera;
use super::frame::{FrameStats, PASS_NAMES};

/// Lightmap view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ViewMode {
    /// First-order lightmap only (direct light).
    FirstOrder,
    /// First order + transfer (the relit result).
    Final,
    /// Transfer only: final − first order.
    Indirect,
    /// The paper's layout: first order (left) | final (right).
    SideBySide,
}

/// Where the shown lightmap comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Source {
    /// The bake, relit on the GPU (the normal view).
    Bake,
    /// The CPU mirror of the bake: ray-cast first order + CPU Eq. 9 of the same maps (a check
    /// of the GPU passes, not the truth).
    CpuMirror,
    /// The true reference for the current lights ([`super::reference`]).
    Reference,
    /// `|GPU lightmap − reference|` relative to the reference's RMS, false colour.
    Error,
}

/// Debug view replacing the lightmap.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DebugView {
    /// No debug view.
    Off,
    /// Covered texels in chart colours, chart borders red, holes black.
    Coverage,
    /// Texels per m² in false colour (log scale).
    Density,
    /// The transfer term of one offset map.
    MapContribution,
}

impl DebugView {
    /// The words the viewer's menu shows for the view.
    pub fn label(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Coverage => "coverage + chart borders",
            Self::Density => "texel density",
            Self::MapContribution => "one offset map",
        }
    }
}

/// Default relative error shown red in the error view.
pub const DEFAULT_ERROR_SCALE: f64 = 0.5;

/// Keyboard shortcuts, as listed in the help overlay.
pub const SHORTCUTS: &[(&str, &str)] = &[
    ("H / F1", "show or hide this help"),
    (
        "1 2 3 4",
        "first order | final | indirect only | side by side",
    ),
    (
        "R",
        "reference on/off: the truth for these lights (exact solve or path-traced)",
    ),
    (
        "E",
        "error view on/off: |lightmap − reference| / RMS(reference), false colour",
    ),
    (
        "M",
        "CPU mirror on/off: ray-traced first order + CPU transfer of the same maps",
    ),
    (
        "D",
        "cycle debug views: off, coverage + chart borders, texel density, one map",
    ),
    ("[ ]", "fewer / more transfer maps (first K by importance)"),
    ("+ −", "exposure × 1.25 / ÷ 1.25"),
    (
        "A",
        "automatic exposure (95th percentile of the final lightmap)",
    ),
    ("F", "frame the mesh"),
    ("P / L / I", "add a point / spot / directional light"),
    ("Delete", "remove the selected light"),
    ("Tab", "select the next light"),
    ("S / F12", "screenshot of the 3D view (PNG)"),
    (
        "Ctrl+S / Ctrl+O",
        "save / load the lights (scene-file fragment)",
    ),
    ("Esc", "close the help; Ctrl+Q quits"),
    ("left drag", "orbit; on a light's handle: move the light"),
    ("right / middle drag", "pan"),
    ("wheel", "zoom"),
];

/// The keys [`AppState::shortcuts`] reacts to.
const SHORTCUT_KEYS: [Key; 27] = [
    Key::H,
    Key::F1,
    Key::Num1,
    Key::Num2,
    Key::Num3,
    Key::Num4,
    Key::R,
    Key::E,
    Key::M,
    Key::D,
    Key::OpenBracket,
    Key::CloseBracket,
    Key::Plus,
    Key::Equals,
    Key::Minus,
    Key::A,
    Key::F,
    Key::P,
    Key::L,
    Key::I,
    Key::Delete,
    Key::Tab,
    Key::S,
    Key::F12,
    Key::O,
    Key::Q,
    Key::Escape,
];

/// Everything the user can change, and what the frame loop reports back.
pub struct AppState {
    /// The lights (scene-file types: metres, W/sr, W/m²).
    pub lights: Vec<Light>,
    /// Selected light.
    pub selected: Option<usize>,
    /// The camera.
    pub camera: OrbitCamera,
    /// Framed bounding sphere (centre, radius m), for `F`.
    pub bounds: (Vec3, f32),
    /// Lightmap view.
    pub mode: ViewMode,
    /// Debug view.
    pub debug: DebugView,
    /// Where the shown lightmap comes from (bake, CPU mirror, reference, error view).
    pub source: Source,
    /// Paths per texel of the path-traced reference.
    pub reference_spp: u32,
    /// Relative error shown red in the error view (blue is 0).
    pub error_scale: f64,
    /// Map index shown by [`DebugView::MapContribution`] (position in importance order).
    pub debug_map: usize,
    /// Exposure (multiplies radiance `B/π` before tonemapping).
    pub exposure: f32,
    /// Number of transfer maps used (first K by importance).
    pub k: usize,
    /// Number of maps in the bake (with pieces).
    pub map_count: usize,
    /// Help overlay shown.
    pub show_help: bool,
    /// Size of the 3D view in physical pixels (set by the UI).
    pub view_px: [u32; 2],
    /// Light set-up file for save / load.
    pub lights_path: String,
    /// Last message for the status line (errors included).
    pub status: String,
    /// Requests for the frame loop.
    pub req: Requests,
    /// Figures shown in the stats panel.
    pub stats: Stats,
    /// Largest shadow-map layer count (6 per point light, 1 per spot/directional;
    /// [`super::SHADOW_LAYERS`]).
    pub max_shadow_layers: u32,
    drag: Option<Drag>,
    /// The camera was framed for the real view size.
    framed: bool,
}

/// What the UI asked the frame loop to do.
#[derive(Clone, Debug, Default)]
pub struct Requests {
    /// Write a screenshot.
    pub screenshot: bool,
    /// Recompute the automatic exposure.
    pub auto_exposure: bool,
    /// Save the lights to `lights_path`.
    pub save_lights: bool,
    /// Load the lights from `lights_path`.
    pub load_lights: bool,
    /// Quit.
    pub quit: bool,
}

/// Figures for the stats panel.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    /// Frames per second (smoothed).
    pub fps: f64,
    /// Last frame.
    pub frame: FrameStats,
    /// Adapter name and backend.
    pub adapter: String,
    /// Number of atlases.
    pub atlases: usize,
    /// Lightmap size.
    pub lightmap: (u32, u32),
    /// Covered texels.
    pub covered: usize,
    /// Extra line from the debug view (e.g. density range).
    pub debug_note: String,
    /// The reference's state (computing, ready, failed); empty when not in use.
    pub reference_note: String,
    /// The viewer's lightmap against the reference, when the reference is ready.
    pub error: Option<ErrorStats>,
}

/// The GPU's lightmap against the reference ([`ortm::accuracy::compare`]).
#[derive(Clone, Debug)]
pub struct ErrorStats {
    /// Relative RMSE of the total over interior texels.
    pub total: f64,
    /// Relative RMSE of the indirect term over interior texels.
    pub indirect: f64,
    /// Power of the lightmap over the reference's (mean of RGB).
    pub energy_ratio: f64,
    /// Interior texels.
    pub interior: usize,
    /// Reference's RMS over interior texels of the map the error view shows, W/m².
    pub rms_w_m2: f64,
    /// What the error view shows (total, indirect, first order).
    pub shown: &'static str,
    /// The path-traced reference's own error (RMS standard error over RMS value, interior).
    pub reference_noise: Option<f64>,
}

/// What a left drag in the 3D view is doing.
#[derive(Clone, Copy, Debug)]
enum Drag {
    Orbit,
    Light(usize),
}

impl AppState {
    /// Initial state: the given lights, the camera framing `bounds`, all maps.
    pub fn new(lights: Vec<Light>, bounds: (Vec3, f32), map_count: usize) -> Self {
        Self {
            selected: (!lights.is_empty()).then_some(0),
            lights,
            camera: OrbitCamera::framing(
                bounds.0,
                bounds.1,
                super::camera::DEFAULT_FOV_DEG,
                4.0 / 3.0,
            ),
            framed: false,
            bounds,
            mode: ViewMode::Final,
            debug: DebugView::Off,
            source: Source::Bake,
            reference_spp: super::reference::DEFAULT_SPP,
            error_scale: DEFAULT_ERROR_SCALE,
            debug_map: 0,
            exposure: 1.0,
            k: map_count,
            map_count,
            show_help: false,
            view_px: [640, 480],
            lights_path: "lights.toml".into(),
            status: String::new(),
            req: Requests::default(),
            stats: Stats::default(),
            max_shadow_layers: super::SHADOW_LAYERS,
            drag: None,
        }
    }

    /// Shadow layers the lights need.
    fn layers(lights: &[Light]) -> u32 {
        ortm::render::shadow_layers_for(lights)
    }

    /// A new light of kind `kind` (`p`oint, `s`pot, `d`irectional) placed in front of the
    /// camera, if the shadow-layer budget allows.
    pub fn add_light(&mut self, kind: char) {
        let (c, r) = self.bounds;
        let eye_dir = self.camera.back();
        let pos = c + (eye_dir + Vec3::Y * 0.5).normalize() * (1.5 * r);
        let light = match kind {
            'p' => Light::Point {
                position_m: pos,
                color: Vec3::ONE,
                intensity_w_sr: self.suggested_intensity(r),
            },
            's' => Light::Spot {
                position_m: pos,
                direction: (c - pos).normalize_or(Vec3::NEG_Z),
                color: Vec3::ONE,
                intensity_w_sr: self.suggested_intensity(r),
                inner_deg: 20.0,
                outer_deg: 30.0,
            },
            _ => Light::Directional {
                direction: (-(eye_dir + Vec3::Y)).normalize_or(Vec3::NEG_Y),
                color: Vec3::ONE,
                irradiance_w_m2: 1.0,
            },
        };
        let mut next = self.lights.clone();
        next.push(light);
        if Self::layers(&next) > self.max_shadow_layers {
            self.status = format!(
                "cannot add the light: {} shadow-map layers needed, this viewer has {} (6 per point \
                 light, 1 per spot or directional light)",
                Self::layers(&next),
                self.max_shadow_layers
            );
            return;
        }
        self.lights = next;
        self.selected = Some(self.lights.len() - 1);
    }

    /// Intensity (W/sr) giving about 1 W/m² at distance `1.5 r`: `I = E·d²`.
    fn suggested_intensity(&self, r: f32) -> f32 {
        (1.5 * r).powi(2)
    }

    /// Frames the mesh in the current view (one half of it in side-by-side).
    pub fn frame_mesh(&mut self) {
        let [w, h] = self.view_px;
        let w = if self.mode == ViewMode::SideBySide {
            w / 2
        } else {
            w
        };
        let aspect = w.max(1) as f32 / h.max(1) as f32;
        self.camera =
            OrbitCamera::framing(self.bounds.0, self.bounds.1, self.camera.fov_y_deg, aspect);
    }

    /// Removes the selected light.
    pub fn remove_selected(&mut self) {
        if let Some(i) = self.selected
            && i < self.lights.len()
        {
            self.lights.remove(i);
            self.selected = if self.lights.is_empty() {
                None
            } else {
                Some(i.min(self.lights.len() - 1))
            };
        }
    }

    /// Where a light's handle is drawn: its position, or for a directional light a point
    /// "up-stream" of the scene centre.
    pub fn handle_position(&self, l: &Light) -> Vec3 {
        match *l {
            Light::Point { position_m, .. } | Light::Spot { position_m, .. } => position_m,
            Light::Directional { direction, .. } => {
                self.bounds.0 - direction.normalize_or(Vec3::NEG_Y) * (1.5 * self.bounds.1)
            }
        }
    }

    /// Applies keyboard shortcuts (not while a text field has focus).
    pub fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let (pressed, ctrl) = ctx.input(|i| {
            (
                SHORTCUT_KEYS
                    .into_iter()
                    .filter(|k| i.key_pressed(*k))
                    .collect::<Vec<_>>(),
                i.modifiers.command || i.modifiers.ctrl,
            )
        });
        for k in pressed {
            match (k, ctrl) {
                (Key::S, true) => self.req.save_lights = true,
                (Key::O, true) => self.req.load_lights = true,
                (Key::Q, true) => self.req.quit = true,
                (_, true) => {}
                (Key::H | Key::F1, _) => self.show_help = !self.show_help,
                (Key::Escape, _) => self.show_help = false,
                (Key::Num1, _) => self.mode = ViewMode::FirstOrder,
                (Key::Num2, _) => self.mode = ViewMode::Final,
                (Key::Num3, _) => self.mode = ViewMode::Indirect,
                (Key::Num4, _) => self.mode = ViewMode::SideBySide,
                (Key::R, _) => self.toggle(Source::Reference),
                (Key::E, _) => self.toggle(Source::Error),
                (Key::M, _) => self.toggle(Source::CpuMirror),
                (Key::D, _) => {
                    self.debug = match self.debug {
                        DebugView::Off => DebugView::Coverage,
                        DebugView::Coverage => DebugView::Density,
                        DebugView::Density if self.map_count > 0 => DebugView::MapContribution,
                        _ => DebugView::Off,
                    }
                }
                (Key::OpenBracket, _) => self.k = self.k.saturating_sub(1),
                (Key::CloseBracket, _) => self.k = (self.k + 1).min(self.map_count),
                (Key::Plus | Key::Equals, _) => self.exposure *= 1.25,
                (Key::Minus, _) => self.exposure /= 1.25,
                (Key::A, _) => self.req.auto_exposure = true,
                (Key::F, _) => self.frame_mesh(),
                (Key::P, _) => self.add_light('p'),
                (Key::L, _) => self.add_light('s'),
                (Key::I, _) => self.add_light('d'),
                (Key::Delete, _) => self.remove_selected(),
                (Key::Tab, _) if !self.lights.is_empty() => {
                    self.selected = Some(self.selected.map_or(0, |s| (s + 1) % self.lights.len()))
                }
                (Key::S | Key::F12, _) => self.req.screenshot = true,
                _ => {}
            }
        }
        self.exposure = self.exposure.clamp(1e-6, 1e6);
    }

    /// Shows `s`, or the bake when `s` is already shown.
    pub fn toggle(&mut self, s: Source) {
        self.source = if self.source == s { Source::Bake } else { s };
    }

    /// Draws the whole UI for one frame; `image` is the 3D view's texture (last frame).
    pub fn ui(&mut self, ui: &mut egui::Ui, image: Option<egui::TextureId>) {
        let ctx = ui.ctx().clone();
        self.shortcuts(&ctx);
        egui::Panel::left("ortm.view.controls")
            .resizable(false)
            .exact_size(340.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.controls(ui));
            });
        egui::Panel::bottom("ortm.view.status").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.label(format!("{:.1} fps", self.stats.fps));
                ui.separator();
                ui.label(if self.status.is_empty() {
                    "H: help"
                } else {
                    self.status.as_str()
                });
            });
        });
        egui::CentralPanel::default()
            .frame(egui::Frame::NONE.fill(Color32::from_rgb(16, 16, 20)))
            .show(ui, |ui| self.view_3d(ui, image));
        if self.show_help {
            egui::Window::new("Help: ortm view")
                .collapsible(false)
                .resizable(false)
                .anchor(egui::Align2::CENTER_CENTER, Vec2::ZERO)
                .show(&ctx, |ui| {
                    egui::Grid::new("ortm.view.help")
                        .striped(true)
                        .show(ui, |ui| {
                            for (k, what) in SHORTCUTS {
                                ui.monospace(*k);
                                ui.label(*what);
                                ui.end_row();
                            }
                        });
                    if ui.button("Close (Esc)").clicked() {
                        self.show_help = false;
                    }
                });
        }
    }

    /// The 3D view: the rendered image, light handles, camera and light dragging.
    fn view_3d(&mut self, ui: &mut egui::Ui, image: Option<egui::TextureId>) {
        let ppp = ui.ctx().pixels_per_point();
        let avail = ui.available_size();
        let (rect, resp) = ui.allocate_exact_size(avail, Sense::click_and_drag());
        self.view_px = [
            ((rect.width() * ppp).round() as u32).max(2),
            ((rect.height() * ppp).round() as u32).max(1),
        ];
        if !self.framed {
            // Frame the mesh on load, once the view's size is known.
            self.frame_mesh();
            self.framed = true;
        }
        if let Some(id) = image {
            ui.painter().image(
                id,
                rect,
                Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                Color32::WHITE,
            );
        }
        // In side-by-side the handles belong to the right (final) half.
        let sub = if self.mode == ViewMode::SideBySide {
            Rect::from_min_max(Pos2::new(rect.center().x, rect.min.y), rect.max)
        } else {
            rect
        };
        let size = [sub.width(), sub.height()];
        let handles: Vec<Option<Pos2>> = self
            .lights
            .iter()
            .map(|l| {
                self.camera
                    .project(self.handle_position(l), size)
                    .map(|p| sub.min + Vec2::new(p[0], p[1]))
            })
            .collect();
        self.draw_handles(&ui.painter_at(rect), &handles, sub);
        self.overlay(&ui.painter_at(rect), rect);
        self.mouse(ui, &resp, &handles, sub);
    }

    /// The reference's state (top left) and, in the error view, the colour scale (bottom
    /// left) over the 3D view.
    fn overlay(&self, painter: &egui::Painter, rect: Rect) {
        let font = egui::FontId::proportional(14.0);
        if matches!(self.source, Source::Reference | Source::Error)
            && !self.stats.reference_note.is_empty()
        {
            let mut text = self.stats.reference_note.clone();
            if let Some(e) = &self.stats.error {
                text += &format!(
                    "\nGPU lightmap vs reference, {} interior texels: relative RMSE total \
                     {:.1} %, indirect {:.1} %, energy ratio {:.3}",
                    e.interior,
                    100.0 * e.total,
                    100.0 * e.indirect,
                    e.energy_ratio
                );
            }
            let galley = painter.layout(text, font.clone(), Color32::WHITE, rect.width() - 16.0);
            let at = rect.min + Vec2::new(8.0, 8.0);
            painter.rect_filled(
                Rect::from_min_size(at, galley.size()).expand(4.0),
                4.0,
                Color32::from_black_alpha(160),
            );
            painter.galley(at, galley, Color32::WHITE);
        }
        if self.source == Source::Error
            && let Some(e) = &self.stats.error
        {
            let (w, h) = (200.0, 14.0);
            let at = Pos2::new(rect.min.x + 12.0, rect.max.y - 40.0);
            painter.rect_filled(
                Rect::from_min_size(at, Vec2::new(w, h + 20.0)).expand(4.0),
                4.0,
                Color32::from_black_alpha(160),
            );
            let steps = 50;
            for i in 0..steps {
                let c = super::debug::ramp((i as f32 + 0.5) / steps as f32);
                let srgb = c.map(|v| (passes::cpu::display::srgb_encode(v) * 255.0) as u8);
                let x0 = at.x + w * i as f32 / steps as f32;
                painter.rect_filled(
                    Rect::from_min_max(
                        Pos2::new(x0, at.y),
                        Pos2::new(x0 + w / steps as f32 + 0.5, at.y + h),
                    ),
                    0.0,
                    Color32::from_rgb(srgb[0], srgb[1], srgb[2]),
                );
            }
            let label = |x: f32, align, text: String| {
                painter.text(
                    Pos2::new(x, at.y + h + 2.0),
                    align,
                    text,
                    egui::FontId::proportional(12.0),
                    Color32::WHITE,
                );
            };
            label(at.x, egui::Align2::LEFT_TOP, "0".into());
            label(
                at.x + w,
                egui::Align2::RIGHT_TOP,
                format!("{}: ≥ {:.3} × RMS", e.shown, self.error_scale),
            );
        }
    }

    /// Draws each light's handle (at its screen position in `handles`, `None` when off
    /// screen) in its colour, the selected one larger, with a line along the direction of
    /// spot and directional lights; `sub` is the view the handles are projected into.
    fn draw_handles(&self, painter: &egui::Painter, handles: &[Option<Pos2>], sub: Rect) {
        let size = [sub.width(), sub.height()];
        for (i, (h, l)) in handles.iter().zip(&self.lights).enumerate() {
            let Some(p) = h else { continue };
            let c = l.color();
            let m = c.max_element().max(1e-6);
            let fill = Color32::from_rgb(
                (255.0 * c.x / m) as u8,
                (255.0 * c.y / m) as u8,
                (255.0 * c.z / m) as u8,
            );
            let sel = self.selected == Some(i);
            painter.circle(
                *p,
                if sel { 9.0 } else { 7.0 },
                fill,
                Stroke::new(
                    if sel { 3.0 } else { 1.5 },
                    if sel { Color32::YELLOW } else { Color32::BLACK },
                ),
            );
            // Direction of spot and directional lights.
            if let Some(d) = l.direction() {
                let from = self.handle_position(l);
                let to = from + d.normalize_or(Vec3::NEG_Y) * (0.4 * self.bounds.1);
                if let Some(q) = self.camera.project(to, size) {
                    painter.line_segment(
                        [*p, sub.min + Vec2::new(q[0], q[1])],
                        Stroke::new(2.0, fill),
                    );
                }
            }
        }
    }

    /// Mouse input on the 3D view: a left drag on a handle moves that light, elsewhere it
    /// orbits; right or middle drag pans; the wheel zooms.
    fn mouse(&mut self, ui: &egui::Ui, resp: &egui::Response, handles: &[Option<Pos2>], sub: Rect) {
        if resp.drag_started_by(egui::PointerButton::Primary) {
            let at = resp.interact_pointer_pos();
            let hit = at.and_then(|a| {
                handles
                    .iter()
                    .enumerate()
                    .filter_map(|(i, h)| h.map(|p| (i, p.distance(a))))
                    .filter(|(_, d)| *d <= 12.0)
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(i, _)| i)
            });
            self.drag = Some(match hit {
                Some(i) => {
                    self.selected = Some(i);
                    Drag::Light(i)
                }
                None => Drag::Orbit,
            });
        }
        if resp.dragged_by(egui::PointerButton::Primary) {
            let d = resp.drag_delta();
            match self.drag {
                Some(Drag::Light(i)) if i < self.lights.len() => {
                    self.move_light(i, d.x, d.y, sub.height());
                }
                _ => self.camera.orbit(d.x, d.y),
            }
        } else if resp.dragged_by(egui::PointerButton::Secondary)
            || resp.dragged_by(egui::PointerButton::Middle)
        {
            let d = resp.drag_delta();
            self.camera.pan(d.x, d.y, sub.height());
        }
        if resp.drag_stopped() {
            self.drag = None;
        }
        if resp.hovered() {
            let scroll = ui.ctx().input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.camera.zoom(scroll / 50.0);
            }
        }
    }

    /// Moves light `i` by a drag of `(dx, dy)` points in a view `height` points tall.
    fn move_light(&mut self, i: usize, dx: f32, dy: f32, height: f32) {
        let handle = self.handle_position(&self.lights[i]);
        let moved = self.camera.drag_point(handle, dx, dy, height);
        let centre = self.bounds.0;
        match &mut self.lights[i] {
            Light::Point { position_m, .. } | Light::Spot { position_m, .. } => *position_m = moved,
            Light::Directional { direction, .. } => {
                *direction = (centre - moved).normalize_or(*direction)
            }
        }
    }

    /// The left panel: view choices, lights, stats.
    fn controls(&mut self, ui: &mut egui::Ui) {
        self.view_controls(ui);
        ui.separator();
        self.lights_controls(ui);
        ui.separator();
        self.stats_grid(ui);
    }

    /// View, number of maps, exposure, shown source (bake, reference, error, CPU mirror),
    /// debug view.
    fn view_controls(&mut self, ui: &mut egui::Ui) {
        ui.heading("View");
        ui.horizontal_wrapped(|ui| {
            ui.radio_value(&mut self.mode, ViewMode::FirstOrder, "first order");
            ui.radio_value(&mut self.mode, ViewMode::Final, "final");
            ui.radio_value(&mut self.mode, ViewMode::Indirect, "indirect only");
            ui.radio_value(&mut self.mode, ViewMode::SideBySide, "side by side");
        });
        ui.add_enabled(
            self.map_count > 0,
            egui::Slider::new(&mut self.k, 0..=self.map_count).text("maps (first K by importance)"),
        );
        ui.horizontal(|ui| {
            let mut log_e = self.exposure.log2();
            if ui
                .add(egui::Slider::new(&mut log_e, -20.0..=20.0).text("exposure (log₂)"))
                .changed()
            {
                self.exposure = 2f32.powf(log_e);
            }
            if ui.button("auto").clicked() {
                self.req.auto_exposure = true;
            }
        });
        self.source_controls(ui);
        egui::ComboBox::from_label("debug view")
            .selected_text(self.debug.label())
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut self.debug, DebugView::Off, "off");
                ui.selectable_value(
                    &mut self.debug,
                    DebugView::Coverage,
                    "coverage + chart borders",
                );
                ui.selectable_value(&mut self.debug, DebugView::Density, "texel density");
                if self.map_count > 0 {
                    ui.selectable_value(
                        &mut self.debug,
                        DebugView::MapContribution,
                        "one offset map",
                    );
                }
            });
        if self.debug == DebugView::MapContribution && self.map_count > 0 {
            ui.add(
                egui::Slider::new(&mut self.debug_map, 0..=self.map_count - 1)
                    .text("map (by importance)"),
            );
        }
    }

    /// Bake / reference / error view / CPU mirror, the reference's samples, the error scale.
    fn source_controls(&mut self, ui: &mut egui::Ui) {
        ui.horizontal_wrapped(|ui| {
            ui.label("show");
            ui.radio_value(&mut self.source, Source::Bake, "bake (GPU)");
            ui.radio_value(&mut self.source, Source::Reference, "reference");
            ui.radio_value(&mut self.source, Source::Error, "error");
            ui.radio_value(&mut self.source, Source::CpuMirror, "CPU mirror");
        });
        ui.add(
            egui::Slider::new(&mut self.reference_spp, 1..=4096)
                .logarithmic(true)
                .text("reference paths/texel (path tracer)"),
        );
        if self.source == Source::Error {
            ui.add(
                egui::Slider::new(&mut self.error_scale, 0.01..=4.0)
                    .logarithmic(true)
                    .text("error shown red (× RMS)"),
            );
        }
    }

    /// The light list with add / remove buttons, the selected light's fields, save / load.
    fn lights_controls(&mut self, ui: &mut egui::Ui) {
        ui.heading("Lights");
        ui.horizontal(|ui| {
            if ui.button("+ point").clicked() {
                self.add_light('p');
            }
            if ui.button("+ spot").clicked() {
                self.add_light('s');
            }
            if ui.button("+ directional").clicked() {
                self.add_light('d');
            }
        });
        let mut remove = None;
        for i in 0..self.lights.len() {
            let sel = self.selected == Some(i);
            let name = self.lights[i].type_name();
            ui.horizontal(|ui| {
                if ui.selectable_label(sel, format!("{i}: {name}")).clicked() {
                    self.selected = Some(i);
                }
                if ui.small_button("remove").clicked() {
                    remove = Some(i);
                }
            });
            if sel {
                let centre = self.bounds.0;
                light_editor(ui, &mut self.lights[i], centre);
            }
        }
        if let Some(i) = remove {
            self.selected = Some(i);
            self.remove_selected();
        }
        ui.horizontal(|ui| {
            ui.label("file");
            ui.text_edit_singleline(&mut self.lights_path);
        });
        ui.horizontal(|ui| {
            if ui.button("save lights").clicked() {
                self.req.save_lights = true;
            }
            if ui.button("load lights").clicked() {
                self.req.load_lights = true;
            }
            if ui.button("screenshot").clicked() {
                self.req.screenshot = true;
            }
        });
    }

    /// Frame rate, per-pass times, maps, atlases, lightmap, adapter.
    fn stats_grid(&self, ui: &mut egui::Ui) {
        ui.heading("Stats");
        let s = &self.stats;
        egui::Grid::new("ortm.view.stats").show(ui, |ui| {
            let mut row = |k: &str, v: String| {
                ui.label(k);
                ui.label(v);
                ui.end_row();
            };
            row("fps", format!("{:.1}", s.fps));
            match s.frame.pass_ms {
                Some(ms) => {
                    for (n, m) in PASS_NAMES.iter().zip(ms) {
                        row(n, format!("{m:.3} ms"));
                    }
                }
                None => row("per pass", "no GPU timestamps".into()),
            }
            row("maps", format!("{} of {}", self.k, self.map_count));
            row("atlases", s.atlases.to_string());
            row("texels blended", s.frame.texel_blends.to_string());
            row(
                "lightmap",
                format!("{}×{} ({} covered)", s.lightmap.0, s.lightmap.1, s.covered),
            );
            row("adapter", s.adapter.clone());
            if !s.debug_note.is_empty() {
                row("debug", s.debug_note.clone());
            }
            if !s.reference_note.is_empty() {
                row("reference", s.reference_note.clone());
            }
            if let Some(e) = &s.error {
                row(
                    "rel. RMSE total",
                    format!("{:.2} % ({} interior texels)", 100.0 * e.total, e.interior),
                );
                row("rel. RMSE indirect", format!("{:.2} %", 100.0 * e.indirect));
                row("energy ratio", format!("{:.4}", e.energy_ratio));
                if let Some(n) = e.reference_noise {
                    row(
                        "reference noise",
                        format!("{:.2} % (std. error)", 100.0 * n),
                    );
                }
                if self.source == Source::Error {
                    row(
                        "error scale",
                        format!(
                            "{}: blue 0 … red ≥ {:.3} × RMS = {:.4e} W/m²",
                            e.shown,
                            self.error_scale,
                            self.error_scale * e.rms_w_m2
                        ),
                    );
                }
            }
        });
    }

    /// Path of the light set-up file.
    pub fn lights_file(&self) -> PathBuf {
        PathBuf::from(&self.lights_path)
    }
}

/// Numeric fields of one light: position, direction (with "aim at the scene centre" for
/// a spot), colour, intensity or irradiance, cone angles.
fn light_editor(ui: &mut egui::Ui, l: &mut Light, centre: Vec3) {
    let vec3 = |ui: &mut egui::Ui, label: &str, v: &mut Vec3, speed: f64| {
        ui.horizontal(|ui| {
            ui.label(label);
            ui.add(egui::DragValue::new(&mut v.x).speed(speed).prefix("x "));
            ui.add(egui::DragValue::new(&mut v.y).speed(speed).prefix("y "));
            ui.add(egui::DragValue::new(&mut v.z).speed(speed).prefix("z "));
        });
    };
    let strength = |ui: &mut egui::Ui, v: &mut f32, unit: &str| {
        ui.add(
            egui::DragValue::new(v)
                .speed(0.01)
                .range(0.0..=1e9)
                .suffix(unit),
        );
    };
    if let Light::Point { position_m, .. } | Light::Spot { position_m, .. } = l {
        vec3(ui, "position (m)", position_m, 0.005);
    }
    match l {
        Light::Spot {
            position_m,
            direction,
            ..
        } => {
            vec3(ui, "direction", direction, 0.01);
            if ui.button("aim at the scene centre").clicked() {
                *direction = (centre - *position_m).normalize_or(*direction);
            }
        }
        Light::Directional { direction, .. } => vec3(ui, "direction (travel)", direction, 0.01),
        Light::Point { .. } => {}
    }
    let (Light::Point { color, .. } | Light::Spot { color, .. } | Light::Directional { color, .. }) =
        l;
    ui.horizontal(|ui| {
        ui.label("colour");
        let mut rgb = color.to_array();
        ui.color_edit_button_rgb(&mut rgb);
        *color = Vec3::from(rgb).max(Vec3::ZERO);
    });
    match l {
        Light::Point { intensity_w_sr, .. } | Light::Spot { intensity_w_sr, .. } => {
            strength(ui, intensity_w_sr, " W/sr")
        }
        Light::Directional {
            irradiance_w_m2, ..
        } => strength(ui, irradiance_w_m2, " W/m²"),
    }
    if let Light::Spot {
        inner_deg,
        outer_deg,
        ..
    } = l
    {
        ui.add(egui::Slider::new(outer_deg, 0.5..=89.0).text("outer cone (°)"));
        ui.add(egui::Slider::new(inner_deg, 0.0..=*outer_deg).text("inner cone (°)"));
        *inner_deg = inner_deg.min(*outer_deg);
    }
    if let Light::Spot { direction, .. } | Light::Directional { direction, .. } = l
        && direction.length_squared() < 1e-12
    {
        *direction = Vec3::NEG_Y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adding_lights_respects_the_shadow_layer_budget() {
        let mut s = AppState::new(Vec::new(), (Vec3::ZERO, 1.0), 3);
        for _ in 0..4 {
            s.add_light('p');
        }
        assert_eq!(s.lights.len(), 4); // 24 layers
        s.add_light('d');
        assert_eq!(s.lights.len(), 4, "a fifth light would need 25 layers");
        assert!(s.status.contains("25"));
        s.selected = Some(1);
        s.remove_selected();
        s.add_light('s');
        assert_eq!(s.lights.len(), 4);
        assert!(matches!(s.lights[3], Light::Spot { .. }));
    }

    #[test]
    fn dragging_a_directional_handle_turns_the_light() {
        let mut s = AppState::new(Vec::new(), (Vec3::ZERO, 1.0), 0);
        s.add_light('d');
        let before = match s.lights[0] {
            Light::Directional { direction, .. } => direction,
            _ => unreachable!(),
        };
        s.move_light(0, 80.0, 0.0, 480.0);
        let after = match s.lights[0] {
            Light::Directional { direction, .. } => direction,
            _ => unreachable!(),
        };
        assert!((after.length() - 1.0).abs() < 1e-5);
        // The handle moved right on screen, so the light now comes from further right:
        // it travels more towards −right.
        let (right, _) = s.camera.right_up();
        assert!(
            after.dot(right) < before.dot(right) - 0.05,
            "{before} → {after}"
        );
    }
}
