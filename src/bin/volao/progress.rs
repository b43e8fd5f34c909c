//! Progress bars on the terminal, and loading a file with one.

use anyhow::Result;
use std::path::Path;
use volao::volume::{self, LoadOptions, Loaded};

/// A progress bar over z-slices for AO precomputation (hidden when not a terminal).
pub fn slice_bar(what: &str, visible: bool) -> indicatif::ProgressBar {
    if !visible {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(1);
    if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
        "{what} {{bar:40}} {{pos}}/{{len}} slices {{eta}}"
    )) {
        bar.set_style(style);
    }
    bar
}

/// Loads a file, with a progress bar on the terminal for anything large.
pub fn load_with_bar(path: &Path, opts: &LoadOptions) -> Result<Loaded> {
    let mut bar: Option<indicatif::ProgressBar> = None;
    let mut progress = |done: u64, total: u64| {
        if total < 32 << 20 {
            return;
        }
        let b = bar.get_or_insert_with(|| {
            let b = indicatif::ProgressBar::new(total);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "loading {bar:40} {bytes}/{total_bytes} {eta}",
            ) {
                b.set_style(style);
            }
            b
        });
        b.set_position(done);
    };
    let loaded = volume::load_with_progress(path, opts, &mut progress);
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let loaded = loaded?;
    for w in &loaded.warnings {
        eprintln!("warning: {}: {w}", volume::display_path(path));
    }
    Ok(loaded)
}
