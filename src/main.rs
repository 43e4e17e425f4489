//! The `raywave` command-line tool.

use clap::{Parser, Subcommand};
use raywave::bench::{bench_trace, TraceBenchOptions};
use raywave::output_line::{warn, OutputLine};
use raywave::render::{render, RenderOptions, RenderView};
use raywave::{BackendOptions, DeviceChoice, TraceMethod};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

/// Wavefront ray-tracing kernels on the CPU and on Vulkan.
#[derive(Parser)]
#[command(name = "raywave", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the CPU backend and every Vulkan device with the ray-tracing features it offers.
    Devices {
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Render a scene: generate → trace → shade (LTC area lights, ratio estimator with stochastic
    /// shadows) → TV-denoise → composite → PNG (and optionally HDR OpenEXR).
    Render(RenderArgs),
    /// Measure stage throughput.
    Bench {
        #[command(subcommand)]
        stage: BenchStage,
    },
    /// Measure accuracy.
    Report {
        #[command(subcommand)]
        topic: ReportTopic,
    },
}

#[derive(Subcommand)]
enum ReportTopic {
    /// Seed 002's variance table (importance warps, light selection, Owen-scrambled Sobol') on the
    /// Cornell box, and the screen-space error spectrum of each sampler.
    Sampling(SamplingReportArgs),
    /// Seed 000's ratio estimator against the fully stochastic one: RMSE against a converged
    /// reference for 1…64 samples per pixel, in shadowed and unshadowed pixels.
    Shade(ShadeReportArgs),
    /// Seed 000's headline result: relMSE against milliseconds for the stochastic and the ratio
    /// estimator, raw and denoised (TV, SVGF baseline), at 1…64 samples per pixel.
    ErrorVsTime(ErrorVsTimeArgs),
}

#[derive(clap::Args)]
struct ErrorVsTimeArgs {
    /// Image side in pixels.
    #[arg(long, default_value_t = 128)]
    resolution: u32,
    #[command(flatten)]
    common: SceneReportArgs,
    /// Also draw the curves into this PNG file.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Steady-state milliseconds: per scene, after its reference, run 1-spp frames untimed in
    /// benchmark mode until their times have not fallen for S seconds (0..=30; 0 still runs one
    /// warm-up round, at least 3 frames and 0.25 s; times still falling S + 30 s in end it, with
    /// a note), then measure in benchmark mode (default: each stage once, as a GPU may run it at
    /// idle clocks).
    #[arg(long, value_name = "S")]
    settle_seconds: Option<f64>,
    #[command(flatten)]
    radius: DenoiseRadiusArg,
}

/// The filters' footprint, an option of `render`, `bench denoise` and `report error-vs-time`.
#[derive(clap::Args)]
struct DenoiseRadiusArg {
    /// Filter radius R in pixels, 1–10 (default: 10·(short side / 1080)^(2/3), rounded, at most
    /// 6 — 6 at 512² and 1080p, 4 at 256², 2 at 128²).
    #[arg(long)]
    denoise_radius: Option<u32>,
}

/// The arguments every scene report takes (see `raywave::report::SceneReportOptions`).
#[derive(clap::Args)]
struct SceneReportArgs {
    /// Scenes, comma-separated: `builtin:NAME` or scene files (.obj, .gltf, .glb), each with a
    /// quad light.
    #[arg(long, default_value = "builtin:cornell,builtin:cornell-two-lights", value_delimiter = ',')]
    scenes: Vec<String>,
    /// Samples per pixel of the reference image.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u32,
    /// Largest sample count measured, a power of two (1, 2, 4, … up to it).
    #[arg(long, default_value_t = 64)]
    max_spp: u32,
    /// Independent repetitions averaged per measurement.
    #[arg(long, default_value_t = 4)]
    reps: u32,
    #[command(flatten)]
    run: ReportRunArgs,
}

impl SceneReportArgs {
    /// The report's options at image side `resolution`, and the backend it runs on; `check`
    /// checks the options (the scene report's and the report's own), before the backend opens.
    fn open(
        self,
        resolution: u32,
        check: impl FnOnce(&raywave::report::SceneReportOptions) -> raywave::Result<()>,
    ) -> raywave::Result<(raywave::report::SceneReportOptions, Box<dyn raywave::Backend>)> {
        let options = raywave::report::SceneReportOptions {
            scenes: self.scenes,
            resolution,
            reference_spp: self.reference_spp,
            max_spp: self.max_spp,
            reps: self.reps,
        };
        // Before the backend opens, which takes a second on a software Vulkan device.
        check(&options)?;
        let backend = self.run.open()?;
        Ok((options, backend))
    }
}

#[derive(clap::Args)]
struct ShadeReportArgs {
    /// Image side in pixels.
    #[arg(long, default_value_t = 64)]
    resolution: u32,
    #[command(flatten)]
    common: SceneReportArgs,
}

#[derive(clap::Args)]
struct SamplingReportArgs {
    /// Image side in pixels (resolution² shading points).
    #[arg(long, default_value_t = 64)]
    resolution: u32,
    /// Independent repetitions per estimator.
    #[arg(long, default_value_t = 256)]
    reps: u32,
    #[command(flatten)]
    run: ReportRunArgs,
}

/// How every report runs and prints: its backend, the validation layers, JSON or a table.
#[derive(clap::Args)]
struct ReportRunArgs {
    /// Backend the report runs on: `cpu` (default), `auto`, `vulkan` or `vulkan:N`.
    #[arg(long, default_value = "cpu")]
    device: String,
    /// Enable the Vulkan validation layers (must be installed; refused with `--device cpu`); any
    /// warning or error they report is printed and fails the command (exit status 1).
    #[arg(long)]
    validate: bool,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
}

impl ReportRunArgs {
    /// The backend a report runs on: `--device`'s, with the Vulkan validation layers if
    /// `--validate` (their messages go to stderr as they arrive, and the report ends with an error
    /// if there were any: [`raywave::close_backend`]); a warning on stderr where `auto` fell back
    /// to the CPU.
    fn open(&self) -> raywave::Result<Box<dyn raywave::Backend>> {
        let options = BackendOptions { validation: self.validate, ..Default::default() };
        let (backend, fallback) = raywave::open_backend_telling_fallback(self.device.parse()?, &options)?;
        if let Some(reason) = fallback {
            warn_vulkan_fallback("the report runs", &reason.to_string());
        }
        Ok(backend)
    }
}

/// Warns on stderr that `--device auto` found no Vulkan device it could open, so that `what` (the
/// render, the report) ran on the CPU, with Vulkan's error `reason`.
fn warn_vulkan_fallback(what: &str, reason: &str) {
    warn(&format!("warning: --device auto found no usable Vulkan device, so {what} on the CPU: {reason}"));
}

#[derive(Subcommand)]
enum BenchStage {
    /// Trace throughput of raywave (CPU and each Vulkan method) and obvhs on the same rays.
    Trace(TraceBenchArgs),
    /// Shading throughput (U of every light and one MIS sample per camera ray), CPU and Vulkan.
    Shade(ShadeBenchArgs),
    /// Seconds and effective bandwidth of each denoise pass for one frame, on the CPU and Vulkan.
    Denoise(DenoiseBenchArgs),
}

#[derive(clap::Args)]
struct DenoiseBenchArgs {
    /// The scene whose frame is denoised.
    #[arg(long, default_value = "builtin:cornell")]
    scene: String,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 1920)]
    width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Samples per pixel of the shaded input.
    #[arg(long, default_value_t = 1)]
    spp: u32,
    /// Timed repetitions per denoiser (the median is reported).
    #[arg(long, default_value_t = 5)]
    repeats: u32,
    /// Skip the Vulkan device.
    #[arg(long)]
    no_vulkan: bool,
    /// Peak memory bandwidth of the Vulkan device in GB/s (default: the datasheet value of the
    /// NVIDIA H100 and H200 models known by their exact device name, none otherwise).
    #[arg(long)]
    peak_gbps: Option<f64>,
    #[command(flatten)]
    radius: DenoiseRadiusArg,
    #[command(flatten)]
    vulkan: VulkanBenchArgs,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args)]
struct TraceBenchArgs {
    /// `builtin:cornell`, `builtin:spheres` (1.3 M triangles), `builtin:hairball` or a scene file
    /// (`.obj`, `.gltf`, `.glb`).
    #[arg(long, default_value = "builtin:spheres")]
    scene: String,
    /// CPU threads; default: 1 and all cores.
    #[arg(long)]
    threads: Option<usize>,
    /// Primary rays per side (resolution² camera rays; shadow and diffuse rays start at their hits).
    #[arg(long, default_value_t = 512)]
    resolution: u32,
    /// obvhs build preset of the BVH: fast (default, chosen by this benchmark), medium or slow.
    #[arg(long, default_value = "fast")]
    bvh: String,
    #[command(flatten)]
    common: BenchArgs,
}

/// What `bench trace` and `bench shade` share: repetitions, the Vulkan device and the output.
#[derive(clap::Args)]
struct BenchArgs {
    /// Timed repetitions per measurement (the median is reported).
    #[arg(long, default_value_t = 3)]
    repeats: u32,
    /// Skip the Vulkan device.
    #[arg(long)]
    no_vulkan: bool,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    vulkan: VulkanBenchArgs,
}

/// How a bench measures the Vulkan device.
#[derive(clap::Args)]
struct VulkanBenchArgs {
    /// Workgroup sizes of the measured Vulkan stage (trace: the compute methods `sw`, `rayquery`;
    /// denoise: the per-pixel passes, the bilateral ones keep 64), comma-separated powers of two
    /// the device runs (default: the stage's preferred size, `WorkgroupSizes::PREFERRED`: shade
    /// 256, the others 64).
    #[arg(long, value_delimiter = ',')]
    workgroup_sizes: Vec<u32>,
    /// Seconds the Vulkan times must have stopped falling before they are measured (0..=30;
    /// default 5, for the GPU's clocks to rise; 0 still runs one warm-up round, at least 3 runs
    /// and 0.25 s; times still falling S + 30 s in end it, with a note).
    #[arg(long)]
    settle_seconds: Option<f64>,
}

impl VulkanBenchArgs {
    fn options(self) -> raywave::bench_device::VulkanBenchOptions {
        raywave::bench_device::VulkanBenchOptions {
            workgroup_sizes: self.workgroup_sizes,
            settle_seconds: self.settle_seconds,
        }
    }
}

#[derive(clap::Args)]
struct ShadeBenchArgs {
    /// The scene shaded: `builtin:cornell`, `builtin:cornell-light-grid` (20 lights), … or a file.
    #[arg(long, default_value = "builtin:cornell")]
    scene: String,
    /// Camera rays per side (resolution² samples, one per pixel).
    #[arg(long, default_value_t = 512)]
    resolution: u32,
    #[command(flatten)]
    common: BenchArgs,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// `builtin:cornell|cornell-two-lights|cornell-light-grid|spheres|hairball` or a Wavefront OBJ / glTF
    /// 2.0 (.gltf, .glb) file.
    #[arg(long, default_value = "builtin:cornell")]
    scene: String,
    /// `auto` (Vulkan if usable, else CPU), `cpu`, `vulkan` or `vulkan:N`.
    #[arg(long, default_value = "auto")]
    device: String,
    /// Trace method: `sw` (CWBVH traversal in the kernels), `rayquery` or `rtpipe` (ray-tracing
    /// pipeline); default: ray query, else the ray-tracing pipeline, else software.
    #[arg(long)]
    trace: Option<String>,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Samples (camera rays, and one shadow ray each) per pixel.
    #[arg(long, default_value_t = 4)]
    spp: u32,
    /// What the image shows: `lit` (direct light with soft shadows) or `normals` (geometry).
    #[arg(long, default_value = "lit")]
    view: String,
    /// Also write the HDR image (linear RGB, 32-bit float OpenEXR).
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Also write the fully stochastic image (emitted radiance + S_N, without the ratio) as PNG,
    /// for comparison.
    #[arg(long)]
    stochastic: Option<PathBuf>,
    /// Denoiser of the shadow ratio: `tv` (seed 000's TV-guided joint bilateral filter), `svgf`
    /// (variance-guided à-trous baseline) or `none` (the raw ratio estimate).
    #[arg(long, default_value = "tv")]
    denoise: String,
    #[command(flatten)]
    radius: DenoiseRadiusArg,
    /// Give each light's analytic specular term the integral of the GGX lobe the LTC table stands
    /// for (the LTC's plus its residual towards GGX): accurate far-tail and grazing-view
    /// highlights (within 1.1 % of a converged reference; the LTC alone is up to 174 % off for
    /// lights that catch only a lobe's tail), for 5–7× the shade stage's time.
    #[arg(long)]
    analytic_residual: bool,
    /// Seed of the sampler.
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Sampler of the pixel and lens positions: `zsobol` (Owen-scrambled Sobol' in Morton order,
    /// blue-noise error), `sobol` (per-pixel shuffled Owen-scrambled Sobol') or `random`.
    #[arg(long, default_value = "zsobol")]
    sampler: String,
    /// Thin-lens aperture radius in scene units (0: pinhole camera).
    #[arg(long, default_value_t = 0.0)]
    aperture: f32,
    /// Distance of the plane in focus (default: the camera's look-at point).
    #[arg(long)]
    focus: Option<f32>,
    /// Enable the Vulkan validation layers (must be installed; refused with `--device cpu`); any
    /// warning or error they report is printed and fails the command (exit status 1).
    #[arg(long)]
    validate: bool,
    /// Steady-state stage times: render untimed frames, in benchmark mode, until their times
    /// have not fallen for S seconds (0..=30; 0 still renders one warm-up round, at least 3
    /// frames and 0.25 s; times still falling S + 30 s in end it, with a note), then time one
    /// more (default: one frame, whose single dispatches a GPU may run at idle clocks). The image
    /// is the same.
    #[arg(long, value_name = "S")]
    settle_seconds: Option<f64>,
    /// Output PNG file.
    #[arg(long)]
    out: PathBuf,
}

fn main() -> ExitCode {
    // A refused setting leaves malloc's default: slower, the same results.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    let _accepted = keep_freed_stream_memory();
    #[cfg(unix)]
    remove_pending_outputs_when_interrupted();
    let cli = Cli::parse();
    let run = || match cli.command {
        Command::Devices { json } => devices(json),
        Command::Render(args) => render_command(args),
        Command::Bench { stage: BenchStage::Trace(args) } => bench_trace_command(args),
        Command::Bench { stage: BenchStage::Shade(args) } => bench_shade_command(args),
        Command::Bench { stage: BenchStage::Denoise(args) } => bench_denoise_command(args),
        Command::Report { topic: ReportTopic::Sampling(args) } => report_sampling_command(args),
        Command::Report { topic: ReportTopic::Shade(args) } => report_shade_command(args),
        Command::Report { topic: ReportTopic::ErrorVsTime(args) } => report_error_vs_time_command(args),
    };
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)) {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(e)) => {
            warn(&format!("error: {}", named_by_flag(e)));
            ExitCode::FAILURE
        }
        Err(payload) if payload.is::<StdoutClosed>() && FILE_PENDING.load(Ordering::Relaxed) => {
            warn("error: standard output closed before the output file was written; none was");
            ExitCode::FAILURE
        }
        Err(payload) if payload.is::<StdoutClosed>() => ExitCode::SUCCESS,
        Err(payload) => match payload.downcast::<StdoutFailed>() {
            Ok(failed) => {
                warn(&format!("error: cannot write standard output: {}", failed.0));
                ExitCode::FAILURE
            }
            Err(payload) => std::panic::resume_unwind(payload),
        },
    }
}

/// Interrupted by SIGINT (Ctrl-C), SIGTERM or SIGHUP, the process would end at once, without
/// unwinding, and leave a `.raywave-…` temporary file beside each output of the unfinished job. A
/// thread waits for these signals instead: it deletes those files
/// ([`raywave::visualize::remove_pending_outputs`], whose guard keeps others from being created)
/// and ends the process by the same signal, with its default action — so that the caller sees
/// what it sent (a shell loop stops on Ctrl-C) and no exit handler runs while another thread may
/// be inside the Vulkan driver. A signal the caller left ignored (`nohup`'s SIGHUP, a background
/// job's SIGINT) stays ignored. Should the handlers fail to install, the signals keep their
/// default action: only the cleanup is lost.
#[cfg(unix)]
fn remove_pending_outputs_when_interrupted() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let handled: Vec<i32> = [SIGINT, SIGTERM, SIGHUP].into_iter().filter(|&signal| !ignored(signal)).collect();
    let mut signals = match signal_hook::iterator::Signals::new(&handled) {
        Ok(signals) => signals,
        Err(e) => {
            warn(&format!("warning: no interrupt handling ({e}): an interrupted render may leave .raywave-… files"));
            return;
        }
    };
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            let _outputs_held = raywave::visualize::remove_pending_outputs();
            // Returns only for a signal signal-hook does not know, which these are not.
            let _ = signal_hook::low_level::emulate_default_handler(signal);
            // SAFETY: `_exit` ends the process at once, running nothing, as the signal would have.
            unsafe { libc::_exit(128 + signal) }
        }
    });
}

/// Whether `signal` is ignored (`SIG_IGN`) in this process, as its parent may have left it.
#[cfg(unix)]
fn ignored(signal: i32) -> bool {
    // SAFETY: `sigaction` with no new action only reads the current one into `current`, a plain
    // C struct for which all zeros is a valid value.
    unsafe {
        let mut current: libc::sigaction = std::mem::zeroed();
        libc::sigaction(signal, std::ptr::null(), &mut current) == 0 && current.sa_sigaction == libc::SIG_IGN
    }
}

/// `error` with the option it names as the command line spells it: the library names its
/// `BackendOptions::validation` field, the flag is `--validate`.
fn named_by_flag(error: raywave::Error) -> raywave::Error {
    match error {
        raywave::Error::InvalidParameter { name: "validation", reason } => {
            raywave::Error::InvalidParameter { name: "validate", reason }
        }
        other => other,
    }
}

/// What [`print_line`] unwinds with when stdout has closed, for `main` to catch.
struct StdoutClosed;

/// Whether the command has an output file still to write (`report error-vs-time --plot`): a
/// closed stdout then ends it with a failure, not quietly, since part of what it was asked for
/// is abandoned (the pending file deletes its temporary file as the stack unwinds).
static FILE_PENDING: AtomicBool = AtomicBool::new(false);

/// What [`print_line`] unwinds with when stdout failed otherwise (a full disk, an I/O error): the
/// lines are the product of a bench or a report, so `main` reports the error and fails.
struct StdoutFailed(std::io::Error);

/// Keeps the memory of freed streams in the process for the next pass (glibc). Each stage of the
/// CPU backend returns new stream buffers, megabytes a pass, and glibc's malloc by default maps
/// blocks that large from the kernel and unmaps them when freed — its mapping threshold rises
/// only to the largest block freed so far (at most 32 MiB), and free memory above
/// `M_TRIM_THRESHOLD` at the top of the heap goes back to the kernel too — so every pass faulted
/// its pages in again: 13 % of a CPU render of the Cornell box (`perf`, 960×540, 4 spp). Blocks
/// up to 1 GiB (a 4K stream of `Vec4`s is 127 MiB) now come from the heap, and up to 2 GiB of it
/// stays with the process once freed. The library leaves the allocator to the program that links
/// it (see the README's Measurements). Returns whether glibc accepted both settings.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_stream_memory() -> bool {
    // SAFETY: `mallopt` only sets two of malloc's tuning parameters, before any other thread
    // exists; a refused value (return 0) leaves malloc's default.
    unsafe {
        (libc::mallopt(libc::M_MMAP_THRESHOLD, 1 << 30) == 1) & (libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX) == 1)
    }
}

/// Prints one measurement line as soon as it exists; a closed stdout (a broken pipe, e.g. piped
/// into `head`) ends the program quietly, with success — unless an output file is pending
/// ([`FILE_PENDING`]) — instead of panicking, and any other write error (a full disk under
/// `--json > file`) ends it with the error and a failure — it had counted as a closed stdout, so
/// a lost bench result exited 0. It unwinds to `main` rather than exiting on the spot, so that
/// what is on the stack is dropped on the way — a pending output file (`report error-vs-time
/// --plot`) deletes its temporary file, a Vulkan backend releases its device; `resume_unwind`
/// prints no panic message.
fn print_line(line: String) {
    use std::io::Write;
    if let Err(e) = writeln!(std::io::stdout().lock(), "{line}") {
        match e.kind() {
            std::io::ErrorKind::BrokenPipe => std::panic::resume_unwind(Box::new(StdoutClosed)),
            _ => std::panic::resume_unwind(Box::new(StdoutFailed(e))),
        }
    }
}

fn bench_trace_command(args: TraceBenchArgs) -> raywave::Result<()> {
    let cores = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let mut threads = args.threads.map_or_else(|| vec![1, cores], |n| vec![n]);
    threads.dedup();
    let options = TraceBenchOptions {
        scene: args.scene,
        threads,
        resolution: args.resolution,
        repeats: args.common.repeats,
        vulkan: !args.common.no_vulkan,
        bvh: args.bvh.parse()?,
        vulkan_options: args.common.vulkan.options(),
    };
    let json = args.common.json;
    bench_trace(&options, |line| print_line(line.text(json)))
}

fn bench_shade_command(args: ShadeBenchArgs) -> raywave::Result<()> {
    use raywave::bench_shade::{bench_shade, ShadeBenchOptions};
    let options = ShadeBenchOptions {
        scene: args.scene,
        resolution: args.resolution,
        repeats: args.common.repeats,
        vulkan: !args.common.no_vulkan,
        vulkan_options: args.common.vulkan.options(),
    };
    let json = args.common.json;
    bench_shade(&options, |line| print_line(line.text(json)))
}

fn bench_denoise_command(args: DenoiseBenchArgs) -> raywave::Result<()> {
    use raywave::bench_denoise::{bench_denoise, DenoiseBenchOptions};
    let options = DenoiseBenchOptions {
        scene: args.scene,
        width: args.width,
        height: args.height,
        spp: args.spp,
        repeats: args.repeats,
        vulkan: !args.no_vulkan,
        peak_gbps: args.peak_gbps,
        denoise_radius: args.radius.denoise_radius,
        vulkan_options: args.vulkan.options(),
    };
    bench_denoise(&options, |line| print_line(line.text(args.json)))
}

fn report_sampling_command(args: SamplingReportArgs) -> raywave::Result<()> {
    use raywave::report::sampling::{report_sampling, validate, ReportLine, SamplingReportOptions};
    let options = SamplingReportOptions { resolution: args.resolution, reps: args.reps };
    // Before the backend opens, which takes a second on a software Vulkan device.
    validate(&options)?;
    let mut backend = args.run.open()?;
    report_sampling(backend.as_mut(), &options, |line| match line {
        ReportLine::Case(case, result) => print_line(if args.run.json { result.json() } else { result.row(case) }),
        ReportLine::Spectrum(spectrum) => print_line(spectrum.text(args.run.json)),
    })?;
    raywave::close_backend(backend)
}

fn report_shade_command(args: ShadeReportArgs) -> raywave::Result<()> {
    let json = args.common.run.json;
    let (options, mut backend) = args.common.open(args.resolution, |options| options.check())?;
    raywave::report::shade::report_shade(backend.as_mut(), &options, |line| print_line(line.text(json)))?;
    raywave::close_backend(backend)
}

fn report_error_vs_time_command(args: ErrorVsTimeArgs) -> raywave::Result<()> {
    use raywave::report::error_vs_time::{fastest_by_error, plot, report_error_vs_time, ErrorVsTimeOptions};
    // Create the plot's file up front so a bad path fails before the measurements.
    let pending = args
        .plot
        .as_deref()
        .map(|path| raywave::visualize::PendingOutput::create(path, image::ImageFormat::Png))
        .transpose()?;
    FILE_PENDING.store(pending.is_some(), Ordering::Relaxed);
    let json = args.common.run.json;
    let (denoise_radius, settle_seconds) = (args.radius.denoise_radius, args.settle_seconds);
    let with = |report| ErrorVsTimeOptions { report, denoise_radius, settle_seconds };
    let (report, mut backend) = args.common.open(args.resolution, |report| with(report.clone()).check())?;
    let options = with(report);
    if !json {
        // The JSON lines name it each (`backend`).
        print_line(format!("backend  {}", backend.name()));
    }
    let lines = report_error_vs_time(backend.as_mut(), &options, |line| print_line(line.text(json)))?;
    if !json {
        print_line(String::new());
        for row in fastest_by_error(&lines) {
            print_line(row.row());
        }
    }
    let title = format!("{}², R = {}, {}", options.report.resolution, options.radius(), backend.name());
    // Before the plot: a run the validation layers faulted draws none.
    raywave::close_backend(backend)?;
    match pending {
        Some(output) => plot(&lines, &title, output),
        None => Ok(()),
    }
}

fn render_command(args: RenderArgs) -> raywave::Result<()> {
    let device = args.device.parse::<DeviceChoice>()?;
    let trace = args.trace.as_deref().map(str::parse::<TraceMethod>).transpose()?;
    let options = RenderOptions {
        scene: args.scene,
        device,
        width: args.width,
        height: args.height,
        spp: args.spp,
        seed: args.seed,
        sampler: raywave::frame::parse_sampler_kind(&args.sampler)?,
        lens_radius: args.aperture,
        focus_distance: args.focus,
        view: args.view.parse()?,
        out: args.out,
        exr: args.exr,
        stochastic: args.stochastic,
        denoise: args.denoise.parse()?,
        denoise_radius: args.radius.denoise_radius,
        analytic_residual: args.analytic_residual,
        backend: BackendOptions { validation: args.validate, trace, ..Default::default() },
        settle_seconds: args.settle_seconds,
    };
    let report = render(&options)?;
    print_line(format!("backend  {}", report.backend));
    if let Some(reason) = &report.vulkan_fallback {
        warn_vulkan_fallback("the render runs", reason);
    }
    print_line(format!(
        "scene    {} ({} triangles, {} zero-area dropped, {} quad lights)",
        options.scene, report.triangles, report.dropped_degenerate, report.lights
    ));
    // What the scene asked for that the render leaves out or renders otherwise, each a warning
    // where it occurs: counts as "N what of SCENE rest".
    let (scene, unrendered) = (&options.scene, &report.unrendered);
    let counted = |count: usize, what: &str, rest: &str| {
        (count > 0).then(|| format!("warning: {count} {what} of {scene} {rest}"))
    };
    let warnings = [
        counted(
            report.unsupported_emitters,
            "emissive mesh(es)",
            "are not one planar parallelogram: they glow where seen (their front faces) but light nothing",
        ),
        counted(
            unrendered.textured_meshes,
            "mesh(es)",
            "have textures or vertex colours, which raywave does not sample: their materials' factors alone apply \
             (an emissive texture's mesh emits its factor everywhere)",
        ),
        counted(
            unrendered.see_through_meshes,
            "mesh(es)",
            "have see-through materials (alpha blended or masked, glTF transmission, MTL dissolve), which raywave \
             renders opaque",
        ),
        counted(
            unrendered.unlit_meshes,
            "mesh(es)",
            "have unlit materials (KHR_materials_unlit), which raywave shades as lit",
        ),
        counted(
            unrendered.deformed_meshes,
            "mesh(es)",
            "have a skin or weighted morph targets, which raywave does not apply: they render in their rest pose",
        ),
        counted(
            unrendered.point_and_line_primitives,
            "glTF primitive(s)",
            "draw points or lines, which raywave does not render (it traces surfaces only)",
        ),
        unrendered.orthographic_camera.then(|| {
            format!(
                "warning: the cameras of {scene} are orthographic, which raywave does not render: it frames the scene \
                 with a perspective camera instead"
            )
        }),
        counted(
            unrendered.punctual_lights,
            "punctual light(s) (KHR_lights_punctual point, spot or directional)",
            "light nothing: raywave renders area lights only (emissive parallelograms)",
        ),
        (report.lights == 0 && options.view == RenderView::Lit).then(|| {
            format!("warning: {scene} has no quad light, so nothing is lit (emitters glow where their front faces are seen)")
        }),
        // Else the summary's "0 of N camera rays hit" alone said why the image is empty.
        (report.hits == 0).then(|| {
            format!("warning: no camera ray hit {scene}: its camera sees none of it (looks away from it?), so the image is empty")
        }),
    ];
    for warning in warnings.into_iter().flatten() {
        warn(&warning);
    }
    let spp = report.samples_per_pixel;
    let rays = u64::from(options.width) * u64::from(options.height) * u64::from(spp);
    print_line(format!(
        "image    {}×{} at {spp} spp → {} ({} of {rays} camera rays hit)",
        options.width,
        options.height,
        options.out.display(),
        report.hits
    ));
    print_line(format!("streams  {} bytes/pixel", report.stream_bytes_per_pixel));
    if let Some(peak) = report.peak_resident_bytes {
        print_line(format!("memory   peak {} MB resident", peak.div_ceil(1_000_000)));
    }
    print_line(match report.warm_up_seconds {
        None => "timing   one frame (a GPU may have run it at idle clocks: --settle-seconds S for steady state)".into(),
        Some(warm_up) => {
            format!("timing   steady state: the frame after {warm_up:.1} s of warm-up frames")
        }
    });
    let name_width = report.timings.iter().map(|t| t.stage.chars().count()).max().unwrap_or(0);
    for t in &report.timings {
        let sanitized = if t.sanitized > 0 { format!("  ({} sanitized)", t.sanitized) } else { String::new() };
        let dispatches = match report.warm_up_seconds {
            Some(_) => format!("  ({} dispatch{} timed)", t.dispatches, if t.dispatches == 1 { "" } else { "es" }),
            None => String::new(),
        };
        print_line(format!("stage    {:<name_width$} {:>10.3} ms{dispatches}{sanitized}", t.stage, t.seconds * 1e3));
    }
    let sanitized = raywave::StageReport::total_sanitized(&report.timings);
    if sanitized > 0 {
        warn(&format!(
            "warning: {sanitized} value(s) went non-finite and were replaced (rays or hits as misses, samples \
             without their contribution, colours by the emitted radiance); see the stage lines"
        ));
    }
    Ok(())
}

#[cfg(feature = "vulkan")]
fn vulkan_devices() -> Result<Vec<serde_json::Value>, String> {
    raywave::vulkan::enumerate_devices().map_err(|e| e.to_string()).map(|list| {
        list.into_iter()
            .map(|d| {
                let preferred = raywave::WorkgroupSizes::preferred_on(&d.workgroup_sizes);
                let preferred: serde_json::Map<_, _> = raywave::StreamStage::ALL
                    .into_iter()
                    .map(|stage| {
                        let name = stage.field_name().trim_start_matches("workgroup_sizes.");
                        (name.to_owned(), preferred.of(stage).into())
                    })
                    .collect();
                let lacks = d.missing_for_kernels();
                serde_json::json!({
                    "backend": "vulkan", "index": d.index, "name": d.name, "type": d.device_type,
                    "api_version": d.api_version, "ray_query": d.ray_query,
                    "acceleration_structure": d.acceleration_structure,
                    "ray_tracing_pipeline": d.ray_tracing_pipeline,
                    "buffer_device_address": d.buffer_device_address, "timestamps": d.timestamps,
                    "can_trace": d.missing_for_ray_query().is_empty(),
                    "runs_kernels": lacks.is_empty(), "lacks": lacks,
                    "workgroup_sizes": d.workgroup_sizes,
                    "preferred_workgroup_sizes": preferred,
                })
            })
            .collect()
    })
}

#[cfg(not(feature = "vulkan"))]
fn vulkan_devices() -> Result<Vec<serde_json::Value>, String> {
    Err("built without the `vulkan` feature".into())
}

fn devices(json: bool) -> raywave::Result<()> {
    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let vulkan = vulkan_devices();
    if json {
        let value = serde_json::json!({
            "cpu": { "backend": "cpu", "threads": threads },
            "vulkan": vulkan.as_ref().ok(),
            "vulkan_error": vulkan.as_ref().err(),
        });
        print_line(value.to_string());
        return Ok(());
    }
    print_line(format!("cpu        {threads} threads (rayon)"));
    match vulkan {
        Ok(list) if list.is_empty() => print_line("vulkan     no devices".into()),
        Ok(list) => {
            for d in list {
                let flag = |k: &str| {
                    if d[k].as_bool() == Some(true) {
                        "yes"
                    } else {
                        "no"
                    }
                };
                let sizes = d["workgroup_sizes"].as_array().map_or(&[][..], Vec::as_slice);
                let sizes = match (sizes.first(), sizes.last()) {
                    (Some(least), Some(most)) => format!("{least}..={most}"),
                    _ => "none".to_owned(),
                };
                let lacks = d["lacks"].as_array().map_or(&[][..], Vec::as_slice);
                let lacks: Vec<&str> = lacks.iter().filter_map(|l| l.as_str()).collect();
                let unusable =
                    if lacks.is_empty() { String::new() } else { format!("  UNUSABLE, lacks: {}", lacks.join(", ")) };
                print_line(format!(
                    "vulkan:{:<3} {} ({}, Vulkan {})  ray_query={} acceleration_structure={} ray_tracing_pipeline={} buffer_device_address={} workgroup_sizes={sizes}{unusable}",
                    d["index"].to_string(), d["name"].as_str().unwrap_or("?"), d["type"].as_str().unwrap_or("?"), d["api_version"].as_str().unwrap_or("?"),
                    flag("ray_query"), flag("acceleration_structure"), flag("ray_tracing_pipeline"), flag("buffer_device_address"),
                ));
            }
        }
        Err(e) => print_line(format!("vulkan     unavailable: {e}")),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    /// glibc takes both settings (a value out of its range would leave the default).
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[test]
    fn glibc_accepts_the_stream_memory_settings() {
        assert!(super::keep_freed_stream_memory());
    }
}
