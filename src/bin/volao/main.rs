//! The `volao` command line: `volao` (viewer), `view`, `info`, `convert`, `render`, `slice`,
//! `ao`, `batch`, `gpu`, `bench`. One module per command; the flags are in `args`.

mod ao;
mod args;
mod batch;
mod bench;
mod convert;
mod gpu;
mod info;
mod progress;
mod render;
mod slice;
mod view;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "volao",
    version,
    about = "Direct volume rendering with exact, clip-aware ambient occlusion"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Open the viewer on a volume file or a scene (.json). `volao` alone opens it on the
    /// built-in demo volume.
    View(Box<args::ViewArgs>),
    /// Describe a volume: format, size, spacing, type, value range, orientation, histogram.
    /// Without FILE, describes the built-in demo volume.
    Info(args::InfoArgs),
    /// Convert between formats, chosen by the output's extension (.nii, .nii.gz, .pvm, .raw).
    Convert(args::ConvertArgs),
    /// Render a volume or a scene file to PNG, headless.
    Render(Box<args::RenderArgs>),
    /// One axial, coronal or sagittal slice to PNG, in patient orientation (radiological:
    /// the patient's right on the image's left), one pixel per voxel.
    Slice(Box<args::SliceArgs>),
    /// Compute an ambient-occlusion volume in the input's geometry and write it.
    Ao(args::AoArgs),
    /// Render many scenes (and their AO volumes) in one process on one device; skips
    /// outputs that exist, reports failed scenes and goes on.
    Batch(args::BatchArgs),
    /// Show the GPU adapter volao will use and run a compute self-test on it.
    Gpu,
    /// Benchmarks (results go to docs/benchmarks.md).
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

#[allow(unsafe_code, reason = "set_var before any thread exists; see SAFETY")]
fn main() {
    if let Some(dir) = volao::process::private_runtime_dir() {
        // SAFETY: first statement of main: no other thread exists yet that could read
        // the environment concurrently.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir) };
    }
    volao::process::exit_quietly_on_broken_pipe();
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        // One line: the error and its causes, joined.
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        None => view::run_demo(),
        Some(Command::View(args)) => view::run(&args),
        Some(Command::Info(args)) => info::run(&args),
        Some(Command::Convert(args)) => convert::run(&args),
        Some(Command::Gpu) => gpu::run(),
        Some(Command::Render(args)) => render::run(&args),
        Some(Command::Ao(args)) => ao::run(&args),
        Some(Command::Slice(args)) => slice::run(&args),
        Some(Command::Batch(args)) => batch::run(&args),
        Some(Command::Bench(command)) => bench::run(&command),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn cli_definition_is_consistent() {
        use clap::CommandFactory;
        super::Cli::command().debug_assert();
    }
}
