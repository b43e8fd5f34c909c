//! Process-level setup for the `volao` binary: a private XDG runtime dir for Mesa, and a
//! quiet exit when stdout is a closed pipe (`volao info FILE | head`).

use std::path::PathBuf;

/// A private runtime dir (`$TMPDIR/volao-runtime-<user>`, by `$USER` or the uid, mode 0700) to offer
/// Mesa when `XDG_RUNTIME_DIR` is unset or unusable; `None` when the current one is fine
/// or none could be made. Setting the variable is left to `main`, before any thread.
///
/// Without it Mesa prints `error: XDG_RUNTIME_DIR is invalid or not set` on every
/// headless run that opens a device, which users read as volao failing.
pub fn private_runtime_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("XDG_RUNTIME_DIR")
        && std::path::Path::new(&dir).is_dir()
    {
        return None;
    }
    // One directory per user, reused by every run (a per-process name would leave one
    // empty directory behind per run).
    let owner = std::env::var("USER")
        .ok()
        .or_else(uid)
        .unwrap_or_else(|| std::process::id().to_string());
    let name: String = owner
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == '-')
        .collect();
    let dir = std::env::temp_dir().join(format!("volao-runtime-{name}"));
    std::fs::create_dir_all(&dir).ok()?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::{MetadataExt, PermissionsExt};
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).ok()?;
        // Someone else's directory of that name is not ours to use: compare its owner
        // with the owner of a file we create.
        let owner = std::fs::metadata(&dir).ok()?.uid();
        let probe = dir.join(format!(".probe-{}", std::process::id()));
        std::fs::write(&probe, b"").ok()?;
        let me = std::fs::metadata(&probe).map(|m| m.uid());
        let _ = std::fs::remove_file(&probe);
        if me.ok()? != owner {
            return None;
        }
    }
    Some(dir)
}

/// The real user id, where the OS shows it (`/proc/self` belongs to it on Linux).
fn uid() -> Option<String> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata("/proc/self")
            .ok()
            .map(|m| m.uid().to_string())
    }
    #[cfg(not(unix))]
    None
}

/// Makes a panic caused by writing to a closed stdout (`println!` after the reader of a
/// pipe went away) end the process quietly with exit status 0, as `cat` or `ls` do.
/// Every other panic keeps the default report.
pub fn exit_quietly_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if is_broken_pipe_message(msg) {
            std::process::exit(0);
        }
        if is_containing() {
            return; // reported as an error by `contain`'s caller
        }
        default(info);
    }));
}

/// Whether a panic message is std's "failed printing to stdout: Broken pipe".
pub fn is_broken_pipe_message(msg: &str) -> bool {
    msg.starts_with("failed printing to std") && msg.contains("Broken pipe")
}

thread_local! {
    /// Set while [`contain`] runs third-party decoding code on this thread.
    static CONTAINING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs third-party parsing code that may panic on malformed input (dicom-rs does, e.g.
/// in its RLE decoder) and turns a panic into `Err(message)`. The panic hook installed
/// by [`exit_quietly_on_broken_pipe`] stays silent for these, so a damaged file gets one
/// error line, not a panic report.
pub fn contain<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    let was = CONTAINING.with(|c| c.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    CONTAINING.with(|c| c.set(was));
    result.map_err(|payload| {
        payload
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| payload.downcast_ref::<&str>().map(|s| (*s).to_owned()))
            .unwrap_or_else(|| "panic".to_owned())
    })
}

/// Whether this thread is inside [`contain`] (for panic hooks).
pub fn is_containing() -> bool {
    CONTAINING.with(|c| c.get())
}
