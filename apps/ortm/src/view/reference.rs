//! The viewer's true reference: the lightmap the bake aims at, for the lights on screen,
//! computed in the background so the UI never waits for it.
//!
//! # Which reference
//! - **Exact dense solve** where the covered texels fit
//!   ([`ortm::bake::transport::dense::MAX_TEXELS`]): the transport system over every covered
//!   texel is assembled and factorised once ([`DenseTransport::new`], `n(n−1)/2` visibility
//!   rays, and [`DenseTransport::factor`], `O(n³)`: seconds), then each lighting is one
//!   [`FactoredTransport::solve`] (`O(n²)`) of the ray-cast first order averaged over each
//!   texel's square, the final started from the centres' first order as `ortm solve` does
//!   by default ([`ortm::bake::lighting::first_order_and_input`]; the reported first order is
//!   the centres'), plus skin's near field resolved at the same sub-texels
//!   ([`ortm::bake::near_field`], as `ortm solve --near-field 3`: README, "The subsurface near
//!   field").
//! - **Path-traced reference** otherwise ([`ortm::accuracy::reference::trace`], `spp` paths per
//!   texel, seed [`REFERENCE_SEED`]): progress (fraction, ETA) is shown, and a lighting change
//!   raises the running trace's `cancel` flag and starts a new one.
//!
//! Both use the bake's effects (radiosity, subsurface) and give per covered texel of the grid
//! (grid order) the first order and the final radiosity `B`, W/m², linear RGB.
//!
//! # Data flow
//! [`ReferenceState::request`] (UI thread, every frame) → a [`Request`] keyed by the lights
//! (and `spp` for the path tracer) → the worker thread (the newest request wins; older ones
//! are dropped or cancelled) → a finished result back over a channel → the state's small cache
//! of finished results (the last [`CACHE`] lightings), which `request` answers from.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glam::Vec3;
use ortm::accuracy::reference::{ReferenceError, Settings, trace};
use ortm::bake::lighting;
use ortm::bake::near_field::{self, NearField};
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::{DenseTransport, FactoredTransport, MAX_TEXELS};
use ortm::bake::transport::{Effects, Kernels, SetupProgress, texel_patches};
use ortm::scene::{Light, Scene};

/// Default paths per texel of the path-traced reference.
pub const DEFAULT_SPP: u32 = 64;

/// Seed of the path-traced reference (fixed: the same lights give the same picture).
pub const REFERENCE_SEED: u64 = 1;

/// Finished lightings kept (toggling between a few light set-ups is instant).
pub const CACHE: usize = 4;

/// Which reference the user asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// The exact solve where the covered texels fit, else the path tracer.
    Auto,
    /// The exact dense solve (refused above [`MAX_TEXELS`] covered texels).
    Exact,
    /// The path-traced reference.
    PathTraced,
}

/// The reference that is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// [`DenseTransport::solve`].
    Exact,
    /// [`ortm::accuracy::reference::trace`].
    PathTraced,
}

impl Solver {
    /// The solver for `method` on `covered` texels, or why there is none.
    pub fn choose(method: Method, covered: usize) -> Result<Self, String> {
        match method {
            Method::Auto if covered <= MAX_TEXELS => Ok(Self::Exact),
            Method::Auto | Method::PathTraced => Ok(Self::PathTraced),
            Method::Exact if covered <= MAX_TEXELS => Ok(Self::Exact),
            Method::Exact => Err(format!(
                "the exact solve is limited to {MAX_TEXELS} covered texels and this bake has \
                 {covered}: use the path-traced reference (--reference-method path-traced or \
                 auto)"
            )),
        }
    }

    /// Short name for the UI.
    pub fn name(self) -> &'static str {
        match self {
            Self::Exact => "exact dense solve",
            Self::PathTraced => "path-traced",
        }
    }
}

/// A finished reference, per covered texel (grid order), W/m².
#[derive(Clone, Debug)]
pub struct RefMaps {
    /// How it was computed.
    pub solver: Solver,
    /// First order `B_o`.
    pub first_order: Vec<Vec3>,
    /// Final radiosity `B`.
    pub final_b: Vec<Vec3>,
    /// Standard error of `final_b` (path tracer only).
    pub std_error: Option<Vec<Vec3>>,
    /// Paths per texel (path tracer only).
    pub spp: Option<u32>,
    /// Seconds the computation took (the exact solve's one-time assembly included the first
    /// time).
    pub seconds: f64,
}

impl RefMaps {
    /// One line for the UI, e.g. `reference: exact dense solve of 712 texels (1.3 s)`.
    pub fn line(&self) -> String {
        match self.spp {
            Some(spp) => format!(
                "reference: {}, {spp} paths per texel, {} texels ({:.1} s)",
                self.solver.name(),
                self.final_b.len(),
                self.seconds
            ),
            None => format!(
                "reference: {} of {} texels ({:.1} s)",
                self.solver.name(),
                self.final_b.len(),
                self.seconds
            ),
        }
    }

    /// `B − B_o` per texel.
    pub fn indirect(&self) -> Vec<Vec3> {
        self.final_b
            .iter()
            .zip(&self.first_order)
            .map(|(b, o)| *b - *o)
            .collect()
    }
}

/// What the worker is doing for the newest request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Waiting for the worker (it finishes an older, cancelled request first).
    Queued,
    /// Assembling the dense transport system (once).
    Assembling,
    /// Solving for the lights.
    Solving,
    /// Path tracing.
    Tracing,
}

/// Progress of the newest request.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Current stage.
    pub stage: Stage,
    /// Fraction done in this stage, when known (path tracing).
    pub fraction: Option<f64>,
    /// Estimated time left, when known.
    pub eta: Option<Duration>,
    /// Time since the request.
    pub elapsed: Duration,
}

impl Progress {
    /// One line for the UI, e.g. `reference: computing 43 % (ETA 12 s)`.
    pub fn line(&self) -> String {
        let what = match self.stage {
            Stage::Queued => "waiting for the previous computation to stop",
            Stage::Assembling => "assembling the exact transport (once)",
            Stage::Solving => "solving for these lights",
            Stage::Tracing => "path tracing",
        };
        let pct = self
            .fraction
            .map(|f| format!(" {:.0} %", 100.0 * f))
            .unwrap_or_default();
        let eta = self
            .eta
            .map(|e| format!(", ETA {:.0} s", e.as_secs_f64().ceil()))
            .unwrap_or_default();
        format!(
            "reference: computing{pct} ({what}, {:.1} s{eta}); showing the bake's lightmap",
            self.elapsed.as_secs_f64()
        )
    }
}

/// The reference's state for the lights asked for.
#[derive(Debug)]
pub enum Status<'a> {
    /// Finished.
    Ready(&'a RefMaps),
    /// Being computed.
    Computing(Progress),
    /// The computation failed (message).
    Failed(&'a str),
}

/// Shared between the UI and the worker for one request.
struct JobProgress {
    stage: AtomicU8,
    done: AtomicUsize,
    total: AtomicUsize,
    stage_started: Mutex<Instant>,
}

impl JobProgress {
    fn new() -> Self {
        Self {
            stage: AtomicU8::new(Stage::Queued as u8),
            done: AtomicUsize::new(0),
            total: AtomicUsize::new(0),
            stage_started: Mutex::new(Instant::now()),
        }
    }

    fn set_stage(&self, s: Stage) {
        self.stage.store(s as u8, Ordering::Relaxed);
        if let Ok(mut t) = self.stage_started.lock() {
            *t = Instant::now();
        }
    }

    fn stage(&self) -> Stage {
        match self.stage.load(Ordering::Relaxed) {
            x if x == Stage::Assembling as u8 => Stage::Assembling,
            x if x == Stage::Solving as u8 => Stage::Solving,
            x if x == Stage::Tracing as u8 => Stage::Tracing,
            _ => Stage::Queued,
        }
    }
}

/// One lighting to compute.
struct Request {
    key: String,
    lights: Vec<Light>,
    spp: u32,
    cancel: Arc<AtomicBool>,
    progress: Arc<JobProgress>,
}

/// A finished (or failed) request.
struct Done {
    key: String,
    result: Result<RefMaps, String>,
}

/// The newest request, as the UI sees it.
struct Job {
    key: String,
    cancel: Arc<AtomicBool>,
    progress: Arc<JobProgress>,
    started: Instant,
}

/// The reference for the viewer: a worker thread and the cache of its results.
pub struct ReferenceState {
    solver: Solver,
    to_worker: Sender<Request>,
    from_worker: Receiver<Done>,
    current: Option<Job>,
    ready: VecDeque<(String, RefMaps)>,
    failed: Option<(String, String)>,
    requests: usize,
}

impl Drop for ReferenceState {
    fn drop(&mut self) {
        // The worker exits once its channel closes; stop a running trace now.
        if let Some(j) = &self.current {
            j.cancel.store(true, Ordering::Relaxed);
        }
    }
}

impl ReferenceState {
    /// Starts the worker for `scene` at the covered texels of `grid` with the bake's
    /// `effects`; fails when `method` cannot be used here (exact solve too large).
    pub fn new(
        scene: Scene,
        grid: TexelGrid,
        effects: Effects,
        method: Method,
    ) -> Result<Self, String> {
        let solver = Solver::choose(method, grid.texels.len())?;
        let (to_worker, requests) = channel();
        let (done, from_worker) = channel();
        std::thread::Builder::new()
            .name("ortm-view-reference".into())
            .spawn(move || {
                Worker {
                    scene,
                    grid,
                    effects,
                    solver,
                    vis: None,
                    dense: None,
                    kernels: None,
                }
                .run(requests, done)
            })
            .map_err(|e| format!("cannot start the reference thread: {e}"))?;
        Ok(Self {
            solver,
            to_worker,
            from_worker,
            current: None,
            ready: VecDeque::new(),
            failed: None,
            requests: 0,
        })
    }

    /// The solver in use.
    #[cfg(test)]
    pub fn solver(&self) -> Solver {
        self.solver
    }

    /// How many computations were started (cache misses).
    #[cfg(test)]
    pub fn requests_started(&self) -> usize {
        self.requests
    }

    /// The cache key of a lighting: the lights' exact values (and `spp` for the path tracer).
    fn key(&self, lights: &[Light], spp: u32) -> String {
        match self.solver {
            Solver::Exact => format!("exact {lights:?}"),
            Solver::PathTraced => format!("traced {spp} {lights:?}"),
        }
    }

    /// The cached reference for `lights` and `spp`, if any (starts nothing).
    pub fn cached(&self, lights: &[Light], spp: u32) -> Option<&RefMaps> {
        let key = self.key(lights, spp);
        self.ready.iter().find(|(k, _)| *k == key).map(|(_, m)| m)
    }

    /// The reference for `lights` (`spp` paths per texel for the path tracer): the cached result,
    /// or the progress of its computation, which this call starts when needed (cancelling a
    /// running one for other lights). Never blocks.
    pub fn request(&mut self, lights: &[Light], spp: u32) -> Status<'_> {
        let key = self.key(lights, spp);
        self.receive();
        self.start_if_needed(&key, lights, spp);
        self.status(&key)
    }

    /// As [`Self::request`], but waits until the result (or a failure) is there.
    pub fn wait(&mut self, lights: &[Light], spp: u32) -> Status<'_> {
        let key = self.key(lights, spp);
        self.receive();
        self.start_if_needed(&key, lights, spp);
        while self.current.as_ref().is_some_and(|j| j.key == key) {
            match self.from_worker.recv() {
                Ok(d) => self.store(d),
                Err(_) => {
                    self.current = None;
                    self.failed = Some((key.clone(), "the reference thread stopped".into()));
                }
            }
        }
        self.status(&key)
    }

    /// Takes the finished results off the channel.
    fn receive(&mut self) {
        while let Ok(d) = self.from_worker.try_recv() {
            self.store(d);
        }
    }

    fn store(&mut self, d: Done) {
        if self.current.as_ref().is_some_and(|j| j.key == d.key) {
            self.current = None;
        }
        match d.result {
            Ok(m) => {
                self.ready.retain(|(k, _)| *k != d.key);
                self.ready.push_front((d.key, m));
                self.ready.truncate(CACHE);
            }
            Err(e) => self.failed = Some((d.key, e)),
        }
    }

    fn start_if_needed(&mut self, key: &str, lights: &[Light], spp: u32) {
        let known = self.ready.iter().any(|(k, _)| k == key)
            || self.failed.as_ref().is_some_and(|(k, _)| k == key)
            || self.current.as_ref().is_some_and(|j| j.key == key);
        if known {
            return;
        }
        if let Some(old) = self.current.take() {
            old.cancel.store(true, Ordering::Relaxed);
        }
        let job = Job {
            key: key.to_string(),
            cancel: Arc::new(AtomicBool::new(false)),
            progress: Arc::new(JobProgress::new()),
            started: Instant::now(),
        };
        let sent = self.to_worker.send(Request {
            key: key.to_string(),
            lights: lights.to_vec(),
            spp,
            cancel: Arc::clone(&job.cancel),
            progress: Arc::clone(&job.progress),
        });
        self.requests += 1;
        if sent.is_err() {
            self.failed = Some((key.to_string(), "the reference thread stopped".into()));
        } else {
            self.current = Some(job);
        }
    }

    fn status(&self, key: &str) -> Status<'_> {
        if let Some((_, m)) = self.ready.iter().find(|(k, _)| k == key) {
            return Status::Ready(m);
        }
        if let Some((k, e)) = &self.failed
            && k == key
        {
            return Status::Failed(e);
        }
        match &self.current {
            Some(j) => Status::Computing(progress_of(j)),
            None => Status::Failed("internal: no reference computation for these lights"),
        }
    }
}

/// The progress snapshot of `job` (fraction and ETA from the path tracer's texel count).
fn progress_of(job: &Job) -> Progress {
    let p = &job.progress;
    let stage = p.stage();
    let (done, total) = (
        p.done.load(Ordering::Relaxed),
        p.total.load(Ordering::Relaxed),
    );
    let fraction = (stage == Stage::Tracing && total > 0).then(|| done as f64 / total as f64);
    let in_stage = p
        .stage_started
        .lock()
        .map_or(Duration::ZERO, |t| t.elapsed());
    let eta = fraction
        .filter(|f| *f > 0.0)
        .map(|f| in_stage.mul_f64((1.0 - f) / f));
    Progress {
        stage,
        fraction,
        eta,
        elapsed: job.started.elapsed(),
    }
}

/// The worker thread's state: the scene and what it built once.
struct Worker {
    scene: Scene,
    grid: TexelGrid,
    effects: Effects,
    solver: Solver,
    vis: Option<Arc<Visibility>>,
    dense: Option<FactoredTransport>,
    /// The dense solve's kernels, for the subsurface near field of each lighting.
    kernels: Option<Kernels>,
}

impl Worker {
    /// Serves requests until the state is dropped; only the newest waiting request is
    /// computed, cancelled ones are skipped.
    fn run(mut self, requests: Receiver<Request>, done: Sender<Done>) {
        while let Ok(mut req) = requests.recv() {
            while let Ok(newer) = requests.try_recv() {
                req = newer;
            }
            if req.cancel.load(Ordering::Relaxed) {
                continue;
            }
            let t0 = Instant::now();
            let result = catch_unwind(AssertUnwindSafe(|| self.compute(&req)));
            if req.cancel.load(Ordering::Relaxed) {
                // Superseded while it ran (an exact solve cannot stop midway): dropped, so
                // what is cached is always what was last asked for.
                continue;
            }
            let result = match result {
                Ok(Ok(mut m)) => {
                    m.seconds = t0.elapsed().as_secs_f64();
                    Ok(m)
                }
                Ok(Err(ReferenceError::Cancelled)) => continue,
                Err(panic) => Err(format!(
                    "the {} reference failed: {}",
                    self.solver.name(),
                    panic_message(&panic)
                )),
            };
            if done
                .send(Done {
                    key: req.key,
                    result,
                })
                .is_err()
            {
                return;
            }
        }
    }

    fn vis(&mut self) -> Arc<Visibility> {
        Arc::clone(
            self.vis
                .get_or_insert_with(|| Arc::new(Visibility::new(&self.scene.mesh))),
        )
    }

    fn compute(&mut self, req: &Request) -> Result<RefMaps, ReferenceError> {
        match self.solver {
            Solver::Exact => Ok(self.exact(req)),
            Solver::PathTraced => self.traced(req),
        }
    }

    /// First order by ray casting, then the exact solve (assembling the system the first
    /// time).
    fn exact(&mut self, req: &Request) -> RefMaps {
        let vis = self.vis();
        if self.dense.is_none() {
            req.progress.set_stage(Stage::Assembling);
            let kernels = Kernels::new(&self.scene, self.effects, Arc::clone(&vis));
            self.dense = Some(DenseTransport::new(&texel_patches(&self.grid), &kernels).factor());
            self.kernels = Some(kernels);
        }
        req.progress.set_stage(Stage::Solving);
        let first_order = lighting::first_order(&self.grid, &req.lights, &vis);
        // The transfer's input averaged over the texels' squares, as `ortm solve` takes it by
        // default: the nearer truth (README, "The transfer's input").
        let translucent = |m: u32| self.scene.is_translucent(m) && self.effects.subsurface;
        // (The sub-texel grid is 3× one that fits the dense solve, far inside the rasteriser's
        // limits; should it fail, the centres' first order is the input.)
        let (first, input) = lighting::first_order_and_input(
            &self.scene,
            &self.grid,
            &req.lights,
            &vis,
            lighting::DEFAULT_FIRST_ORDER_SAMPLES,
            translucent,
        )
        .unwrap_or_else(|_| (first_order.clone(), first_order.clone()));
        // Skin's near field at the input's sub-texels, a source the solve transports (nothing
        // to do without skin; should the sub-texel grid fail, the solve goes without it).
        let delta = self.kernels.as_ref().and_then(|kernels| {
            near_field::correction(
                &self.scene,
                &self.grid,
                kernels,
                &req.lights,
                &vis,
                &input,
                NearField::new(lighting::DEFAULT_FIRST_ORDER_SAMPLES),
                &SetupProgress::none(),
            )
            .ok()
        });
        let mut final_b = self.dense.as_ref().map_or_else(
            || input.clone(),
            |d| d.solve_with_source(&input, delta.as_deref()),
        );
        lighting::with_first_order(&mut final_b, &first, &input);
        RefMaps {
            solver: Solver::Exact,
            first_order,
            final_b,
            std_error: None,
            spp: None,
            seconds: 0.0,
        }
    }

    /// The path-traced reference, with progress and the request's cancel flag.
    fn traced(&mut self, req: &Request) -> Result<RefMaps, ReferenceError> {
        req.progress.set_stage(Stage::Tracing);
        let settings = Settings {
            samples_per_texel: req.spp.max(1),
            replicates: ortm::accuracy::reference::DEFAULT_REPLICATES,
            seed: REFERENCE_SEED,
            effects: self.effects,
        };
        let progress = |done: usize, total: usize| {
            req.progress.total.store(total, Ordering::Relaxed);
            req.progress.done.fetch_max(done, Ordering::Relaxed);
        };
        let r = trace(
            &self.scene,
            &self.grid,
            &req.lights,
            &settings,
            &progress,
            &req.cancel,
        )?;
        Ok(RefMaps {
            solver: Solver::PathTraced,
            first_order: r.first_order,
            final_b: r.final_b,
            std_error: Some(r.std_error),
            spp: Some(r.samples_per_texel),
            seconds: 0.0,
        })
    }
}

fn panic_message(p: &Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ortm::scene::cornell::cornell_box;

    /// The exact solve written out as `ortm solve` does it (its default averaged input).
    fn exact_solve(scene: &Scene, grid: &TexelGrid, lights: &[Light]) -> (Vec<Vec3>, Vec<Vec3>) {
        let vis = Arc::new(Visibility::new(&scene.mesh));
        let kernels = Kernels::new(scene, Effects::default(), Arc::clone(&vis));
        let dense = DenseTransport::new(&texel_patches(grid), &kernels);
        let b_o = lighting::first_order(grid, lights, &vis);
        let (first, input) = lighting::first_order_and_input(
            scene,
            grid,
            lights,
            &vis,
            lighting::DEFAULT_FIRST_ORDER_SAMPLES,
            |m| kernels.is_translucent(m),
        )
        .unwrap();
        let mut b = dense.solve(&input);
        lighting::with_first_order(&mut b, &first, &input);
        (b_o, b)
    }

    fn max_rel_diff(a: &[Vec3], b: &[Vec3]) -> f32 {
        let scale = b.iter().map(|v| v.max_element()).fold(0.0f32, f32::max);
        a.iter()
            .zip(b)
            .map(|(x, y)| (*x - *y).abs().max_element())
            .fold(0.0f32, f32::max)
            / scale
    }

    fn moved(lights: &[Light], dx: f32) -> Vec<Light> {
        lights
            .iter()
            .map(|l| match *l {
                Light::Point {
                    position_m,
                    color,
                    intensity_w_sr,
                } => Light::Point {
                    position_m: position_m + Vec3::new(dx, 0.0, 0.0),
                    color,
                    intensity_w_sr,
                },
                other => other,
            })
            .collect()
    }

    #[test]
    fn the_reference_of_the_cornell_box_is_its_exact_solve() {
        let scene = cornell_box(24);
        let grid = TexelGrid::build(&scene).unwrap();
        assert!(grid.texels.len() <= MAX_TEXELS);
        let mut st = ReferenceState::new(
            scene.clone(),
            grid.clone(),
            Effects::default(),
            Method::Auto,
        )
        .unwrap();
        assert_eq!(st.solver(), Solver::Exact);
        let Status::Ready(r) = st.wait(&scene.lights, DEFAULT_SPP) else {
            panic!("no reference");
        };
        let (b_o, b) = exact_solve(&scene, &grid, &scene.lights);
        // Same computation on another thread: equal up to the LU's summation order.
        let d = max_rel_diff(&r.final_b, &b);
        assert!(d < 1e-5, "final differs by {d} of the maximum");
        assert!(max_rel_diff(&r.first_order, &b_o) < 1e-6);
        // A closed box with interreflection: the final is brighter than the first order.
        let sum = |v: &[Vec3]| v.iter().map(|x| x.element_sum() as f64).sum::<f64>();
        assert!(sum(&r.final_b) > 1.2 * sum(&r.first_order));
    }

    #[test]
    fn a_lights_change_restarts_the_reference_and_the_cache_answers_repeats() {
        let scene = cornell_box(16);
        let grid = TexelGrid::build(&scene).unwrap();
        let a = scene.lights.clone();
        let b = moved(&a, 0.15);
        let mut st = ReferenceState::new(
            scene.clone(),
            grid.clone(),
            Effects::default(),
            Method::Auto,
        )
        .unwrap();
        // Ask for A then at once for B: the reference shown for B is B's, never A's.
        assert!(matches!(st.request(&a, 1), Status::Computing(_)));
        let fin_b = match st.wait(&b, 1) {
            Status::Ready(r) => r.final_b.clone(),
            other => panic!("{other:?}"),
        };
        let (_, want_b) = exact_solve(&scene, &grid, &b);
        assert!(max_rel_diff(&fin_b, &want_b) < 1e-5);
        let started = st.requests_started();
        assert_eq!(started, 2);
        // Same lights again (and spp, which the exact solve ignores): from the cache.
        assert!(matches!(st.request(&b, 99), Status::Ready(_)));
        assert_eq!(st.requests_started(), started);
        // Back to A: a new computation (A's was superseded), equal to A's exact solve.
        let fin_a = match st.wait(&a, 1) {
            Status::Ready(r) => r.final_b.clone(),
            other => panic!("{other:?}"),
        };
        assert_eq!(st.requests_started(), started + 1);
        let (_, want_a) = exact_solve(&scene, &grid, &a);
        assert!(max_rel_diff(&fin_a, &want_a) < 1e-5);
        assert!(max_rel_diff(&fin_a, &fin_b) > 0.05, "the light moved");
        // Both are cached now.
        assert!(matches!(st.request(&b, 1), Status::Ready(_)));
        assert!(matches!(st.request(&a, 1), Status::Ready(_)));
        assert_eq!(st.requests_started(), started + 1);
    }

    #[test]
    fn the_exact_method_is_refused_above_the_dense_limit() {
        assert_eq!(
            Solver::choose(Method::Auto, MAX_TEXELS + 1),
            Ok(Solver::PathTraced)
        );
        let e = Solver::choose(Method::Exact, MAX_TEXELS + 1).unwrap_err();
        assert!(e.contains("path-traced"), "{e}");
        assert_eq!(Solver::choose(Method::Auto, 10), Ok(Solver::Exact));
    }

    #[test]
    fn progress_gives_the_fraction_and_a_linear_eta() {
        let job = Job {
            key: String::new(),
            cancel: Arc::new(AtomicBool::new(false)),
            progress: Arc::new(JobProgress::new()),
            started: Instant::now(),
        };
        let p = progress_of(&job);
        assert_eq!(p.stage, Stage::Queued);
        assert!(p.fraction.is_none() && p.eta.is_none());
        job.progress.set_stage(Stage::Tracing);
        job.progress.total.store(200, Ordering::Relaxed);
        job.progress.done.store(86, Ordering::Relaxed);
        // 43 % done after 10 s in the stage: 10 · 57 / 43 = 13.26 s left.
        *job.progress.stage_started.lock().unwrap() = Instant::now() - Duration::from_secs(10);
        let p = progress_of(&job);
        assert_eq!(p.fraction, Some(0.43));
        let eta = p.eta.unwrap().as_secs_f64();
        assert!((eta - 10.0 * 57.0 / 43.0).abs() < 0.1, "{eta}");
        let line = p.line();
        assert!(
            line.contains("computing 43 %") && line.contains("ETA 14 s"),
            "{line}"
        );
    }
}
