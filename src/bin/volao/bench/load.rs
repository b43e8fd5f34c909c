//! `volao bench load` and `load-one`: load time and peak memory, volao vs nibabel.

use super::median;
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;
use volao::volume::{self, LoadOptions, fmt_bytes};

/// Arguments of `volao bench load`.
#[derive(Debug, clap::Args)]
pub struct LoadBenchArgs {
    /// Folder with the shared test data (nifti/ch2.nii.gz and raw/cranium-ct.raw).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Runs per file and reader; the median time is reported.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Python interpreter with nibabel and numpy installed.
    #[arg(long, default_value = "python3")]
    pub python: String,
}

/// One load measured in a fresh process.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LoadSample {
    pub reader: String,
    pub seconds: f64,
    pub payload_bytes: u64,
    pub rss_before_kb: u64,
    pub hwm_kb: u64,
    /// Mean value, so both readers are seen to read the same numbers.
    pub checksum: f64,
}

impl LoadSample {
    /// Peak memory added by the load, relative to the voxel payload.
    pub fn peak_over_payload(&self) -> f64 {
        (self.hwm_kb.saturating_sub(self.rss_before_kb) * 1024) as f64 / self.payload_bytes as f64
    }
}

fn status_kb(key: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key) && l[key.len()..].starts_with(':'))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// `volao bench load-one FILE`: load once in this process, print a [`LoadSample`] as JSON.
pub fn load_one(path: &Path) -> Result<()> {
    let before = status_kb("VmRSS");
    let start = Instant::now();
    // cranium-ct.raw takes its layout from the InVesalius .plist beside it.
    let loaded = volume::load(path, &LoadOptions::default())?;
    let seconds = start.elapsed().as_secs_f64();
    let sample = LoadSample {
        reader: "volao".into(),
        seconds,
        payload_bytes: loaded.volume.data.byte_len() as u64,
        rss_before_kb: before,
        hwm_kb: status_kb("VmHWM"),
        checksum: loaded.volume.stats().mean,
    };
    println!("{}", serde_json::to_string(&sample)?);
    Ok(())
}

fn run_json(cmd: &mut Command) -> Result<LoadSample> {
    let out = cmd.output().with_context(|| format!("running {cmd:?}"))?;
    if !out.status.success() {
        bail!(
            "{cmd:?} failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim())
        .with_context(|| format!("parsing the output of {cmd:?}: {text}"))
}

/// `volao bench load`: volao vs nibabel/numpy, each load in a fresh process.
pub fn load_bench(args: &LoadBenchArgs) -> Result<()> {
    let exe = std::env::current_exe().context("finding the volao executable")?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/nibabel_load.py");
    let files = [
        args.data.join("nifti/ch2.nii.gz"),
        args.data.join("raw/cranium-ct.raw"),
        args.data.join("dicom/cranium-ct"),
        args.data.join("nrrd/cranium-ct.nrrd"),
    ];
    let runs = args.runs.max(1);
    println!(
        "| file | reader | median load | peak memory over payload | payload | ratio (python / volao time) |"
    );
    println!("|---|---|---|---|---|---|");
    for file in &files {
        if !file.exists() {
            bail!(
                "{}: not found (pass --data with the shared data folder)",
                file.display()
            );
        }
        let mut ours = Vec::new();
        let mut theirs = Vec::new();
        // A DICOM folder: dcm2niix's conversion to NIfTI, for scale (it also writes).
        let mut converted = Vec::new();
        for _ in 0..runs {
            if file.is_dir() {
                converted.push(run_json(
                    Command::new(&args.python)
                        .arg(&script)
                        .arg(file)
                        .arg("--dcm2niix"),
                )?);
            }
            ours.push(run_json(
                Command::new(&exe).args(["bench", "load-one"]).arg(file),
            )?);
            let mut py = Command::new(&args.python);
            py.arg(&script).arg(file);
            if file.extension().is_some_and(|e| e == "raw") {
                py.args(["--raw-dtype", "<i2", "--dims", "256", "256", "108"]);
            }
            theirs.push(run_json(&mut py)?);
        }
        let t_ours = median(ours.iter().map(|s| s.seconds).collect());
        let t_theirs = median(theirs.iter().map(|s| s.seconds).collect());
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let t_conv = if converted.is_empty() {
            0.0
        } else {
            median(converted.iter().map(|s| s.seconds).collect())
        };
        for (samples, t) in [(&ours, t_ours), (&theirs, t_theirs), (&converted, t_conv)] {
            let Some(s) = samples.first() else { continue };
            let peak = median(samples.iter().map(LoadSample::peak_over_payload).collect());
            let ratio = if s.reader == "volao" {
                format!("{:.2}", t_theirs / t_ours)
            } else {
                String::new()
            };
            println!(
                "| {name} | {} | {:.1} ms | {peak:.2}× | {} | {ratio} |",
                s.reader,
                t * 1e3,
                fmt_bytes(s.payload_bytes)
            );
        }
        if (ours[0].checksum - theirs[0].checksum).abs() > 1e-6 * ours[0].checksum.abs().max(1.0) {
            bail!(
                "{name}: volao and python read different values (means {} vs {})",
                ours[0].checksum,
                theirs[0].checksum
            );
        }
    }
    Ok(())
}
