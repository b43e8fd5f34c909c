//! Reading exactly what a header promises from a plain or gzip stream: short reads
//! reported as truncation, gzip trailers (CRC32, length) always checked.

use super::VolumeError;
use std::io::Read;
use std::path::Path;

/// Largest ratio deflate can achieve (≈1032:1): a gzip file of N bytes never inflates to
/// more than this many times N, so a header claiming more is refused before allocating.
pub const MAX_DEFLATE_RATIO: u64 = 1032;

/// Refuses a file that cannot hold `end` bytes (`what`, for the message) before anything
/// is allocated: exactly for a plain file of `exact` bytes, by deflate's largest ratio
/// for a gzip file (`exact` is `None`) whose size gives at most `bound` bytes.
pub fn check_holds(
    path: &Path,
    what: String,
    end: u64,
    exact: Option<u64>,
    bound: u64,
) -> Result<(), VolumeError> {
    match exact {
        Some(len) if len < end => Err(VolumeError::Truncated {
            path: path.to_owned(),
            what,
            expected: end,
            actual: len,
        }),
        None if bound < end => Err(VolumeError::invalid(
            path,
            format!(
                "truncated: {what} need {end} bytes but a gzip file of {} can hold at most {bound}",
                super::fmt_bytes(bound / MAX_DEFLATE_RATIO)
            ),
        )),
        _ => Ok(()),
    }
}

/// Reads exactly `buf.len()` bytes; a short read becomes [`VolumeError::Truncated`]
/// reporting how far the file went (`consumed` bytes were read before this call).
pub fn read_all(
    r: &mut impl Read,
    buf: &mut [u8],
    path: &Path,
    what: &str,
    consumed: u64,
) -> Result<(), VolumeError> {
    let mut done = 0;
    while done < buf.len() {
        match r.read(&mut buf[done..]) {
            Ok(0) => {
                return Err(VolumeError::Truncated {
                    path: path.to_owned(),
                    what: what.to_owned(),
                    expected: consumed + buf.len() as u64,
                    actual: consumed + done as u64,
                });
            }
            Ok(n) => done += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            // A gzip stream cut short: report it as the truncation it is.
            Err(e)
                if e.kind() == std::io::ErrorKind::UnexpectedEof
                    || e.to_string().contains("incomplete") =>
            {
                return Err(VolumeError::Truncated {
                    path: path.to_owned(),
                    what: format!("{what} (compressed stream ends early)"),
                    expected: consumed + buf.len() as u64,
                    actual: consumed + done as u64,
                });
            }
            Err(e) => {
                return Err(VolumeError::invalid(
                    path,
                    format!("{what}: corrupt or unreadable data ({e})"),
                ));
            }
        }
    }
    Ok(())
}

/// Discards `n` bytes (to skip extensions or earlier frames); short → `Truncated`.
pub fn skip(
    r: &mut impl Read,
    n: u64,
    path: &Path,
    what: &str,
    consumed: u64,
) -> Result<(), VolumeError> {
    let got = std::io::copy(&mut r.take(n), &mut std::io::sink())
        .map_err(|e| VolumeError::invalid(path, format!("{what}: {e}")))?;
    if got < n {
        return Err(VolumeError::Truncated {
            path: path.to_owned(),
            what: what.to_owned(),
            expected: consumed + n,
            actual: consumed + got,
        });
    }
    Ok(())
}

/// Reads to the end of a gzip stream so its CRC32 and length are checked.
pub(crate) fn finish_gzip(r: &mut dyn Read, path: &Path) -> Result<(), VolumeError> {
    std::io::copy(r, &mut std::io::sink())
        .map(|_| ())
        .map_err(|e| {
            VolumeError::invalid(
                path,
                format!(
                    "gzip stream is corrupt ({e}): refusing data that fails its CRC32/length check"
                ),
            )
        })
}
