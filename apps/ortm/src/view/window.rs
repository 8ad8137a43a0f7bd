//! The window and frame loop of `ortm view`: winit window, wgpu surface on the same device
//! as the passes, egui (egui-winit input, egui-wgpu painting), and per frame: UI → GPU frame
//! (or a CPU lightmap: debug views, CPU mirror, reference, error view) → egui → present. Also
//! the `--frames N --screenshot out.png` batch mode, which waits for the reference before
//! drawing when it shows the reference or the error view (so its pictures are reproducible).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, anyhow};
use passes::frame::RendererOptions;
use passes::{Gpu, LightDesc, TexelImage};
use winit::application::ApplicationHandler;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop, OwnedDisplayHandle};
use winit::window::{Window, WindowId};

use super::app::{AppState, DebugView, ErrorStats, Source, ViewMode};
use super::debug;
use super::frame::{Shown, ViewRenderer};
use super::reference::{Method, RefMaps, ReferenceState, Status};
use super::{RunOptions, ViewerInput};
use ortm::bake::raycast::Visibility;

/// Runs the viewer until the window closes (or `--frames` frames were drawn).
pub fn run(input: ViewerInput, opts: RunOptions) -> Result<()> {
    let event_loop = EventLoop::new().map_err(|e| {
        anyhow!(
            "cannot open a window: {e} (ortm view needs a display: set DISPLAY, or run it \
             under `xvfb-run -a`)"
        )
    })?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let display = event_loop.owned_display_handle();
    let mut handler = Handler {
        input: Some(input),
        opts,
        display,
        state: None,
        error: None,
        frames: 0,
    };
    event_loop
        .run_app(&mut handler)
        .context("the window's event loop failed")?;
    match handler.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

struct Handler {
    input: Option<ViewerInput>,
    opts: RunOptions,
    display: OwnedDisplayHandle,
    state: Option<Running>,
    error: Option<anyhow::Error>,
    frames: u32,
}

/// Everything alive while the window is open.
struct Running {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
    image_id: Option<(egui::TextureId, [u32; 2])>,
    view: ViewRenderer,
    app: AppState,
    data: ViewerInput,
    vis: Option<Visibility>,
    /// The true reference (started the first time it is shown).
    reference: Option<ReferenceState>,
    /// Why the reference cannot be computed here (e.g. exact solve asked for, too large).
    reference_refused: Option<String>,
    reference_method: Method,
    /// Batch mode: wait for the reference instead of showing the lightmap meanwhile.
    block_on_reference: bool,
    cpu_key: String,
    last_pieces_k: usize,
    last_frame: Instant,
    minimised: bool,
    /// The surface can be copied from (window screenshots).
    copyable: bool,
    /// Write the next presented window image here.
    capture_window: Option<PathBuf>,
}

impl ApplicationHandler for Handler {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_some() {
            return;
        }
        let Some(input) = self.input.take() else {
            return;
        };
        match Running::open(event_loop, self.display.clone(), input, &self.opts) {
            Ok(r) => {
                r.window.request_redraw();
                self.state = Some(r);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(st) = &mut self.state else { return };
        let _ = st.egui_state.on_window_event(&st.window, &event);
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                st.minimised = size.width == 0 || size.height == 0;
                if !st.minimised {
                    st.config.width = size.width;
                    st.config.height = size.height;
                    st.surface.configure(&st.view.gpu.device, &st.config);
                }
                st.window.request_redraw();
            }
            WindowEvent::RedrawRequested => {
                if st.minimised {
                    return;
                }
                if let (Some(n), Some((w, h))) = (self.opts.frames, self.opts.resize)
                    && self.frames == n / 2
                {
                    // Batch-mode resize (tests): the new size arrives as a Resized event.
                    let _ = st
                        .window
                        .request_inner_size(winit::dpi::PhysicalSize::new(w, h));
                }
                if self.opts.frames == Some(self.frames + 1) {
                    if st.copyable {
                        st.capture_window = self.opts.window_screenshot.clone();
                    } else if self.opts.window_screenshot.is_some() {
                        eprintln!(
                            "warning: the window surface cannot be copied from; no window \
                             screenshot"
                        );
                    }
                }
                match st.frame() {
                    Ok(()) => {}
                    Err(e) => {
                        // A frame error (bad light values, GPU error) goes to the status
                        // line; the batch mode stops on it.
                        if self.opts.frames.is_some() {
                            self.error = Some(e);
                            event_loop.exit();
                            return;
                        }
                        st.app.status = format!("error: {e:#}");
                    }
                }
                self.frames += 1;
                if let Some(n) = self.opts.frames
                    && self.frames >= n
                {
                    if let Some(p) = &self.opts.screenshot
                        && let Err(e) = st.screenshot(p)
                    {
                        self.error = Some(e);
                    }
                    st.print_reference_figures();
                    event_loop.exit();
                    return;
                }
                if st.app.req.quit {
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if let Some(st) = &self.state {
            if st.minimised {
                event_loop.set_control_flow(ControlFlow::Wait);
            } else {
                event_loop.set_control_flow(ControlFlow::Poll);
                st.window.request_redraw();
            }
        }
    }
}

impl Running {
    /// Opens the window on the adapter that can draw into it, uploads the bake to the
    /// passes and sets up the UI state from `data` and `opts`.
    fn open(
        event_loop: &ActiveEventLoop,
        display: OwnedDisplayHandle,
        data: ViewerInput,
        opts: &RunOptions,
    ) -> Result<Self> {
        let attrs = Window::default_attributes()
            .with_title(format!("ortm view — {}", data.title))
            .with_inner_size(winit::dpi::PhysicalSize::new(
                opts.window_size.0,
                opts.window_size.1,
            ));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .context("cannot create the window")?,
        );
        let instance = wgpu::Instance::new(
            wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(display)),
        );
        let surface = instance
            .create_surface(Arc::clone(&window))
            .context("cannot create a drawing surface for the window")?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: Some(&surface),
            apply_limit_buckets: false,
        }))
        .map_err(|e| {
            anyhow!(
                "no GPU adapter can draw into the window: {e} (install a Vulkan driver, e.g. \
                 `apt-get install mesa-vulkan-drivers` for the lavapipe software renderer)"
            )
        })?;
        let gpu = Gpu::from_adapter(&adapter)?;
        let (config, copyable) = surface_config(&surface, &adapter, window.inner_size())?;
        surface.configure(&gpu.device, &config);

        let ctx = egui::Context::default();
        let egui_state = egui_winit::State::new(
            ctx,
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(gpu.device.limits().max_texture_dimension_2d as usize),
        );
        let egui_renderer = egui_wgpu::Renderer::new(
            &gpu.device,
            config.format,
            egui_wgpu::RendererOptions::default(),
        );
        let view = view_renderer(gpu, &data)?;
        let app = initial_state(&data, &view, opts);
        let mut st = Self {
            window,
            surface,
            config,
            egui_state,
            egui_renderer,
            image_id: None,
            view,
            last_pieces_k: data.map_order.len(),
            app,
            data,
            vis: None,
            reference: None,
            reference_refused: None,
            reference_method: opts.reference_method,
            block_on_reference: opts.frames.is_some(),
            cpu_key: String::new(),
            last_frame: Instant::now(),
            minimised: false,
            copyable,
            capture_window: None,
        };
        match opts.exposure {
            Some(e) => st.app.exposure = e,
            None => st.auto_exposure()?,
        }
        Ok(st)
    }

    fn light_descs(&self) -> Vec<LightDesc> {
        self.app
            .lights
            .iter()
            .map(ortm::render::light_desc)
            .collect()
    }

    fn auto_exposure(&mut self) -> Result<()> {
        let (_, fin) = self.view.lightmaps(&self.light_descs())?;
        self.app.exposure = ortm::render::auto_exposure(&fin);
        Ok(())
    }

    /// One frame: requests, lightmaps, UI, present.
    fn frame(&mut self) -> Result<()> {
        let now = Instant::now();
        let dt = now.duration_since(self.last_frame).as_secs_f64();
        self.last_frame = now;
        if dt > 0.0 {
            let fps = 1.0 / dt;
            let s = &mut self.app.stats;
            s.fps = if s.fps == 0.0 {
                fps
            } else {
                0.9 * s.fps + 0.1 * fps
            };
        }
        self.handle_requests();
        // A failing 3D frame keeps the UI alive (the error shows in the status line); the
        // batch mode gets the error back.
        let rendered = self.render_3d();
        if let Err(e) = &rendered {
            self.app.status = format!("error: {e:#}");
        }
        self.register_image();

        // UI.
        let raw = self.egui_state.take_egui_input(&self.window);
        let ctx = self.egui_state.egui_ctx().clone();
        let image = self.image_id.map(|(id, _)| id);
        let app = &mut self.app;
        let mut out = ctx.run_ui(raw, |ui| app.ui(ui, image));
        self.egui_state
            .handle_platform_output(&self.window, out.platform_output.clone());
        let jobs = ctx.tessellate(out.shapes, out.pixels_per_point);
        // egui's texture changes: uploads now, frees after painting, whatever happens.
        let mut textures = std::mem::take(&mut out.textures_delta);
        let gpu = &self.view.gpu;
        for (id, deltas) in &textures.set {
            for delta in deltas {
                self.egui_renderer
                    .update_texture(&gpu.device, &gpu.queue, *id, delta);
            }
        }
        let free = std::mem::take(&mut textures.free);
        textures.clear();
        let painted = self.paint(&jobs, out.pixels_per_point);
        for id in &free {
            self.egui_renderer.free_texture(id);
        }
        painted?;
        rendered
    }

    /// Paints egui (which shows the 3D image) into the window and presents it; writes the
    /// window screenshot when one is due.
    fn paint(&mut self, jobs: &[egui::ClippedPrimitive], pixels_per_point: f32) -> Result<()> {
        let gpu = &self.view.gpu;
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&gpu.device, &self.config);
                return Ok(());
            }
            _ => return Ok(()),
        };
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [self.config.width, self.config.height],
            pixels_per_point,
        };
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.view.egui"),
            });
        let extra =
            self.egui_renderer
                .update_buffers(&gpu.device, &gpu.queue, &mut enc, jobs, &screen);
        let target = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        {
            let mut pass = enc
                .begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("ortm.view.egui"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &target,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                })
                .forget_lifetime();
            self.egui_renderer.render(&mut pass, jobs, &screen);
        }
        let capture = self.capture_window.take().map(|p| {
            let (buffer, padded) =
                gpu.record_readback("ortm.view.window_screenshot", &mut enc, &frame.texture, 4);
            (p, buffer, padded)
        });
        gpu.queue.submit(extra.into_iter().chain([enc.finish()]));
        if let Some((path, buffer, padded)) = capture {
            let bytes = gpu.map_read("ortm.view.window_screenshot", &buffer)?;
            let (w, h) = (frame.texture.width(), frame.texture.height());
            let bgra = frame.texture.format() == wgpu::TextureFormat::Bgra8Unorm;
            let mut img = image::RgbaImage::new(w, h);
            for (y, row) in bytes
                .chunks_exact(padded as usize)
                .take(h as usize)
                .enumerate()
            {
                for x in 0..w as usize {
                    let p = &row[4 * x..4 * x + 4];
                    let rgba = if bgra {
                        [p[2], p[1], p[0], 255]
                    } else {
                        [p[0], p[1], p[2], 255]
                    };
                    img.put_pixel(x as u32, y as u32, image::Rgba(rgba));
                }
            }
            crate::output::save_png_atomic(&img, &path)?;
        }
        self.window.pre_present_notify();
        gpu.queue.present(frame);
        gpu.check("ortm.view.egui")?;
        Ok(())
    }

    /// The 3D part of a frame: transfer maps, CPU views, the passes.
    fn render_3d(&mut self) -> Result<()> {
        if self.app.k != self.last_pieces_k {
            let pieces = self.data.pieces_of_first(self.app.k);
            self.last_pieces_k = self.app.k;
            self.view.set_pieces(&pieces)?;
        }
        let shown = self.update_cpu_view()?;
        let lights = self.light_descs();
        let stats = self.view.render(
            self.app.view_px,
            shown,
            &lights,
            self.app.camera.to_camera(),
            self.app.exposure,
        )?;
        self.app.stats.frame = stats;
        Ok(())
    }

    /// Registers (or re-points) the egui texture of the 3D image.
    fn register_image(&mut self) {
        let Some(tex) = &self.view.image else { return };
        let size = [tex.width(), tex.height()];
        let view = tex.create_view(&wgpu::TextureViewDescriptor::default());
        let dev = &self.view.gpu.device;
        match self.image_id {
            Some((id, s)) if s == size => {
                let _ = id;
            }
            Some((id, _)) => {
                self.egui_renderer.update_egui_texture_from_wgpu_texture(
                    dev,
                    &view,
                    wgpu::FilterMode::Linear,
                    id,
                );
                self.image_id = Some((id, size));
            }
            None => {
                let id = self.egui_renderer.register_native_texture(
                    dev,
                    &view,
                    wgpu::FilterMode::Linear,
                );
                self.image_id = Some((id, size));
            }
        }
    }

    /// The frame's lightmap choice; computes and uploads CPU lightmaps when their inputs
    /// changed. While the reference is not ready, the reference and error views show the
    /// bake's lightmap (the stats and the 3D view say so).
    fn update_cpu_view(&mut self) -> Result<Shown> {
        let app = &self.app;
        let gpu_shown = match app.mode {
            ViewMode::FirstOrder => Shown::FirstOrder,
            ViewMode::Final => Shown::Final,
            ViewMode::Indirect => Shown::Indirect,
            ViewMode::SideBySide => Shown::SideBySide,
        };
        let wants_reference =
            app.debug == DebugView::Off && matches!(app.source, Source::Reference | Source::Error);
        let reference_ready = if wants_reference {
            self.poll_reference()?
        } else {
            self.app.stats.reference_note.clear();
            self.app.stats.error = None;
            false
        };
        let app = &self.app;
        if app.debug == DebugView::Off
            && (app.source == Source::Bake || (wants_reference && !reference_ready))
        {
            self.app.stats.debug_note.clear();
            return Ok(gpu_shown);
        }
        // False colours depend on the exposure; lightmaps do not.
        let exposure_key = if app.debug == DebugView::Off && app.source != Source::Error {
            String::new()
        } else {
            app.exposure.to_string()
        };
        let key = format!(
            "{:?} {:?} {:?} {} {} {:?} {} {} {exposure_key}",
            app.debug,
            app.source,
            app.mode,
            app.k,
            app.debug_map,
            app.lights,
            app.reference_spp,
            app.error_scale
        );
        let dilate = app.debug != DebugView::Coverage;
        if key == self.cpu_key {
            return Ok(Shown::Cpu { dilate });
        }
        let t0 = Instant::now();
        let (img, note) = self.cpu_image()?;
        self.view.set_cpu_lightmap(&img)?;
        self.app.stats.debug_note = format!("{note} ({:.0} ms)", t0.elapsed().as_secs_f64() * 1e3);
        self.cpu_key = key;
        Ok(Shown::Cpu { dilate })
    }

    /// The CPU lightmap of the current debug view or source, and its stats note.
    fn cpu_image(&mut self) -> Result<(TexelImage, String)> {
        let exposure = self.app.exposure;
        Ok(match self.app.debug {
            DebugView::Coverage => (
                debug::coverage_view(&self.data.grid, exposure),
                format!(
                    "{} covered texels, chart borders red",
                    self.data.grid.texels.len()
                ),
            ),
            DebugView::Density => {
                let (img, (lo, hi)) = debug::density_view(&self.data.grid, exposure);
                (img, format!("{lo:.3e} (blue) … {hi:.3e} (red) texels/m²"))
            }
            DebugView::MapContribution if self.data.map_order.is_empty() => (
                TexelImage::new(self.data.grid.width, self.data.grid.height),
                "the bake has no transfer maps with stored texels".into(),
            ),
            DebugView::MapContribution => {
                let last = self.data.map_order.len() - 1;
                self.map_contribution_view(self.data.map_order[self.app.debug_map.min(last)])?
            }
            DebugView::Off => match self.app.source {
                Source::CpuMirror | Source::Bake => {
                    let r = self.cpu_mirror()?;
                    let map = match self.app.mode {
                        ViewMode::FirstOrder => r.first_order,
                        ViewMode::Indirect => debug::difference(&r.final_map, &r.first_order),
                        ViewMode::Final | ViewMode::SideBySide => r.final_map,
                    };
                    (
                        debug::with_coverage(&self.data.grid, &map),
                        "CPU mirror: ray-traced first order + CPU Eq. 9 of the bake's maps".into(),
                    )
                }
                Source::Reference | Source::Error => self.reference_views()?,
            },
        })
    }

    /// Starts or polls the reference for the current lights (waits for it in batch mode);
    /// updates the stats' note; true when it is ready.
    fn poll_reference(&mut self) -> Result<bool> {
        if self.reference.is_none() && self.reference_refused.is_none() {
            match ReferenceState::new(
                self.data.scene.clone(),
                self.data.grid.clone(),
                self.data.effects,
                self.reference_method,
            ) {
                Ok(s) => self.reference = Some(s),
                Err(e) => self.reference_refused = Some(e),
            }
        }
        let note = &mut self.app.stats.reference_note;
        let failed = match (&mut self.reference, &self.reference_refused) {
            (_, Some(e)) => e.clone(),
            (None, None) => "internal: no reference".into(),
            (Some(st), None) => {
                let (lights, spp) = (&self.app.lights, self.app.reference_spp);
                let status = if self.block_on_reference {
                    st.wait(lights, spp)
                } else {
                    st.request(lights, spp)
                };
                match status {
                    Status::Ready(m) => {
                        *note = m.line();
                        return Ok(true);
                    }
                    Status::Computing(p) => {
                        *note = p.line();
                        self.app.stats.error = None;
                        // The bake's lightmap is shown meanwhile: the next ready reference
                        // redraws its view and its figures, even for lights seen before.
                        self.cpu_key.clear();
                        return Ok(false);
                    }
                    Status::Failed(e) => e.to_string(),
                }
            }
        };
        *note = format!("reference unavailable: {failed}; showing the bake's lightmap");
        self.app.stats.error = None;
        self.cpu_key.clear();
        if self.block_on_reference {
            anyhow::bail!("{failed}");
        }
        Ok(false)
    }

    /// The reference for the current lights, when it is cached.
    fn cached_reference(&self) -> Option<&RefMaps> {
        self.reference
            .as_ref()?
            .cached(&self.app.lights, self.app.reference_spp)
    }

    /// The reference or error view (the reference must be ready), and the error figures of
    /// the GPU's lightmap (read back) against the reference in the stats.
    fn reference_views(&mut self) -> Result<(TexelImage, String)> {
        let grid = &self.data.grid;
        let r = self
            .cached_reference()
            .context("internal: the reference is not ready")?;
        let (fo, fin) = self.view.lightmaps(&self.light_descs())?;
        let (test_fo, test_fin) = (
            debug::texel_values(grid, &fo),
            debug::texel_values(grid, &fin),
        );
        let c = ortm::accuracy::compare::compare(
            grid,
            &r.final_b,
            &test_fin,
            Some((&r.first_order, &test_fo)),
            0,
        );
        let sub = |a: &[glam::Vec3], b: &[glam::Vec3]| -> Vec<glam::Vec3> {
            a.iter().zip(b).map(|(x, y)| *x - *y).collect()
        };
        // The maps the view shows: the reference's, and the GPU's for the error.
        let (shown, reference, test) = match self.app.mode {
            ViewMode::FirstOrder => ("first order", r.first_order.clone(), test_fo),
            ViewMode::Indirect => ("indirect", r.indirect(), sub(&test_fin, &test_fo)),
            ViewMode::Final | ViewMode::SideBySide => ("total", r.final_b.clone(), test_fin),
        };
        let (values, rms) = debug::error_values(grid, &reference, &test);
        let mask = ortm::accuracy::compare::interior_mask(grid);
        let reference_noise = r.std_error.as_ref().map(|se| {
            let zero = vec![glam::Vec3::ZERO; se.len()];
            ortm::accuracy::compare::relative_rmse(se, &zero, Some(&mask))
                / ortm::accuracy::compare::relative_rmse(&zero, &r.final_b, Some(&mask))
        });
        let e = c.energy_ratio;
        let stats = ErrorStats {
            total: c.total,
            indirect: c.indirect.unwrap_or(f64::NAN),
            energy_ratio: (e.x + e.y + e.z) / 3.0,
            interior: c.interior,
            rms_w_m2: rms,
            shown,
            reference_noise,
        };
        let out = if self.app.source == Source::Error {
            (
                debug::error_view(grid, &values, self.app.error_scale, self.app.exposure),
                format!(
                    "error of the GPU lightmap ({shown}), blue 0 … red ≥ {:.3} × RMS",
                    self.app.error_scale
                ),
            )
        } else {
            let map = ortm::bake::lighting::to_lightmap(grid, &reference);
            (
                debug::with_coverage(grid, &map),
                format!("reference ({shown}): {}", r.solver.name()),
            )
        };
        self.app.stats.error = Some(stats);
        Ok(out)
    }

    /// In batch mode: the reference and the error figures on stdout.
    fn print_reference_figures(&self) {
        if let Some(e) = &self.app.stats.error {
            println!("{}", self.app.stats.reference_note);
            println!(
                "GPU lightmap vs reference, {} interior texels: relative RMSE total {:.4}, \
                 indirect {:.4}, energy ratio {:.4}",
                e.interior, e.total, e.indirect, e.energy_ratio
            );
        }
    }

    /// The one-map debug view of map `m` (its transfer term from the GPU's, or with the
    /// CPU mirror the CPU's, first order), scaled so its 95th percentile shows as the
    /// automatic exposure would show it; and its status note.
    fn map_contribution_view(&mut self, m: u32) -> Result<(TexelImage, String)> {
        let fo = if self.app.source == Source::CpuMirror {
            self.cpu_mirror()?.first_order
        } else {
            let (fo, _) = self.view.lightmaps(&self.light_descs())?;
            debug::to_lightmap(&fo)
        };
        let c = debug::map_contribution(&self.data.set, m, &fo, &self.data.grid.area_map())?;
        let (dx, dy) = self.data.offset_of(m);
        let mut img = debug::with_coverage(&self.data.grid, &c);
        let gain = ortm::render::auto_exposure(&img) / self.app.exposure;
        let gain = if gain.is_finite() && gain > 0.0 {
            gain
        } else {
            1.0
        };
        for p in &mut img.rgba {
            for v in &mut p[..3] {
                *v *= gain;
            }
        }
        Ok((
            img,
            format!("map {m}, offset ({dx}, {dy}) texels, shown ×{gain:.3}"),
        ))
    }

    fn cpu_mirror(&mut self) -> Result<debug::CpuMirror> {
        let vis = self
            .vis
            .get_or_insert_with(|| Visibility::new(&self.data.scene.mesh));
        let keep = self.data.first_maps(self.app.k);
        debug::cpu_mirror(
            (&self.data.scene, &self.data.grid),
            self.data.effects,
            vis,
            &self.data.set,
            (&self.app.lights, self.data.first_order_samples),
            |m| keep.get(m as usize).copied().unwrap_or(false),
        )
    }

    fn handle_requests(&mut self) {
        let req = std::mem::take(&mut self.app.req);
        self.app.req.quit = req.quit;
        if req.auto_exposure
            && let Err(e) = self.auto_exposure()
        {
            self.app.status = format!("auto exposure failed: {e:#}");
        }
        if req.screenshot {
            let name = PathBuf::from(format!(
                "ortm-view-{}.png",
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_secs())
            ));
            self.app.status = match self.screenshot(&name) {
                Ok(()) => format!("wrote {}", name.display()),
                Err(e) => format!("screenshot failed: {e:#}"),
            };
        }
        if req.save_lights {
            let p = self.app.lights_file();
            let text = format!(
                "# Light set-up saved by `ortm view` (scene-file [[light]] tables: metres, W/sr, \
                 W/m²).\n\n{}",
                ortm::scene::file::lights_to_toml(&self.app.lights)
            );
            self.app.status = match ortm::io::write_atomic(&p, text.as_bytes()) {
                Ok(()) => format!("saved {} lights to {}", self.app.lights.len(), p.display()),
                Err(e) => format!("cannot write '{}': {e}", p.display()),
            };
        }
        if req.load_lights {
            let p = self.app.lights_file();
            self.app.status = match ortm::scene::file::load_lights_fragment(&p) {
                Ok(l) if ortm::render::shadow_layers_for(&l) > self.app.max_shadow_layers => {
                    format!(
                        "{}: these lights need {} shadow-map layers, the viewer has {}",
                        p.display(),
                        ortm::render::shadow_layers_for(&l),
                        self.app.max_shadow_layers
                    )
                }
                Ok(l) => {
                    let n = l.len();
                    self.app.lights = l;
                    self.app.selected = (n > 0).then_some(0);
                    format!("loaded {n} lights from {}", p.display())
                }
                Err(e) => format!("cannot load lights: {e}"),
            };
        }
    }

    /// Writes the last rendered 3D image (read back from the GPU) as PNG.
    fn screenshot(&self, path: &Path) -> Result<()> {
        let img = self.view.read_image()?;
        crate::output::save_png_atomic(&img, path)
    }
}

/// The window surface's configuration at `size` (physical pixels) and whether it can be
/// copied from (window screenshots): a non-sRGB format, as egui-wgpu wants ("gamma space";
/// the image holds sRGB values), vsync, the first alpha mode offered.
fn surface_config(
    surface: &wgpu::Surface<'_>,
    adapter: &wgpu::Adapter,
    size: winit::dpi::PhysicalSize<u32>,
) -> Result<(wgpu::SurfaceConfiguration, bool)> {
    let caps = surface.get_capabilities(adapter);
    let format = caps
        .formats
        .iter()
        .copied()
        .find(|f| !f.is_srgb())
        .or_else(|| caps.formats.first().copied())
        .context("the window surface offers no texture format")?;
    let copyable = caps.usages.contains(wgpu::TextureUsages::COPY_SRC)
        && matches!(
            format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm
        );
    let config = wgpu::SurfaceConfiguration {
        usage: if copyable {
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC
        } else {
            wgpu::TextureUsages::RENDER_ATTACHMENT
        },
        format,
        width: size.width.max(1),
        height: size.height.max(1),
        present_mode: wgpu::PresentMode::AutoVsync,
        desired_maximum_frame_latency: 2,
        alpha_mode: caps
            .alpha_modes
            .first()
            .copied()
            .unwrap_or(wgpu::CompositeAlphaMode::Auto),
        view_formats: vec![],
        color_space: wgpu::SurfaceColorSpace::Auto,
    };
    Ok((config, copyable))
}

/// The viewer's passes on `gpu` with the bake of `data` uploaded: [`super::SHADOW_LAYERS`]
/// shadow-map layers of `data.shadow_size`², the adapter's best transfer path, every map
/// (`frame` re-prepares the transfer pass for `--maps K`).
fn view_renderer(gpu: Gpu, data: &ViewerInput) -> Result<ViewRenderer> {
    let options = RendererOptions {
        first_order: passes::first_order::FirstOrderOptions {
            shadow_map_size: data.shadow_size,
            max_shadow_layers: super::SHADOW_LAYERS,
            samples: data.first_order_samples,
            ..Default::default()
        },
        transfer: passes::transfer::TransferOptions::best_for(&gpu),
        display: passes::display::DisplayOptions {
            direct: data.display.direct.direct(),
            sampling: data.display.filter.sampling(),
            ..Default::default()
        },
        ..Default::default()
    };
    let all_pieces = data.pieces_of_first(data.map_order.len());
    let mut r = ViewRenderer::new(
        gpu,
        &options,
        ortm::render::mesh_data(&data.scene.mesh),
        &ortm::render::albedo_map(&data.grid),
        &ortm::render::texel_weights(&data.grid),
        data.atlases.clone(),
        &all_pieces,
    )?;
    if let Some(lengths) = ortm::render::diffusion_lengths(&data.scene, &data.grid, data.effects) {
        r.set_diffusion_lengths(&lengths)?;
    }
    Ok(r)
}

/// The UI state at start: the bake's lights, camera and stats, and the options of the run.
fn initial_state(data: &ViewerInput, view: &ViewRenderer, opts: &RunOptions) -> AppState {
    let mut app = AppState::new(data.lights.clone(), data.bounds(), data.map_order.len());
    app.stats.adapter = format!(
        "{} ({:?})",
        view.gpu.adapter_info.name, view.gpu.adapter_info.backend
    );
    app.stats.atlases = data.atlases.len();
    app.stats.lightmap = (data.grid.width, data.grid.height);
    app.stats.covered = data.grid.texels.len();
    app.status = data.note.clone();
    if let Some(p) = &opts.lights_file {
        app.lights_path = p.display().to_string();
    }
    app.mode = opts.mode;
    app.debug = opts.debug;
    app.source = opts.source;
    app.reference_spp = opts.reference_spp.max(1);
    app.error_scale = opts.error_scale;
    app.debug_map = opts.debug_map.min(app.map_count.saturating_sub(1));
    if let Some(k) = opts.maps {
        app.k = k.min(app.map_count);
    }
    app
}
