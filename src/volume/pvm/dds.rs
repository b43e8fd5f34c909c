//! libmini's Differential Data Stream: measuring, decoding and de-planing a DDS
//! (`v3d`, `v3e`) stream into the PVM file it compresses (see the parent module).

use super::error::PvmError;

/// libmini `DDS_RL`: width of a run's count field.
const DDS_RUN_BITS: u32 = 7;

// ---------------------------------------------------------------------------------------
// DDS decompression (libmini readDDSfile / DDS_decode / DDS_interleave)
// ---------------------------------------------------------------------------------------

/// How a decoded DDS stream is split into byte planes (the layout `DDS_deinterleave`
/// produced and `DDS_interleave` undoes). File bytes are grouped into regions of
/// `block_bytes` (v3e: `skip × 2^24`; 0 for v3d: one region spanning the stream); inside
/// a region of length L the bytes at offsets ≡ c (mod skip) are stored together, plane
/// after plane. Only offsets are computed here: the planar buffer is never reshuffled.
#[derive(Debug, Clone, Copy)]
pub(super) struct Planes {
    pub(super) skip: usize,
    pub(super) block_bytes: usize,
    pub(super) len: usize,
}

impl Planes {
    /// Region containing file position `pos`: (start, length).
    pub(super) fn region(&self, pos: usize) -> (usize, usize) {
        let block = if self.block_bytes == 0 {
            self.len
        } else {
            self.block_bytes
        };
        if block == 0 {
            return (0, 0);
        }
        let base = pos / block * block;
        (base, block.min(self.len.saturating_sub(base)))
    }

    /// Offset inside a region of length `region_len` where plane `c` starts: the number
    /// of positions ≡ 0, 1, …, c−1 (mod skip) in the region.
    pub(super) fn plane_start(&self, region_len: usize, c: usize) -> usize {
        (0..c)
            .map(|k| (region_len + self.skip - 1 - k) / self.skip)
            .sum()
    }

    /// Index in the planar buffer of file byte `pos`.
    pub(super) fn index(&self, pos: usize) -> usize {
        if self.skip <= 1 {
            return pos;
        }
        let (base, region_len) = self.region(pos);
        let r = pos - base;
        base + self.plane_start(region_len, r % self.skip) + r / self.skip
    }

    /// Calls `put(pos − start, byte)` for every file position `pos` in `start..end`,
    /// walking each plane sequentially (no division per byte).
    pub(super) fn gather(
        &self,
        planar: &[u8],
        start: usize,
        end: usize,
        mut put: impl FnMut(usize, u8),
    ) {
        let end = end.min(self.len);
        let skip = self.skip.max(1);
        let mut pos = start;
        while pos < end {
            let (base, region_len) = self.region(pos);
            if region_len == 0 {
                break;
            }
            let region_end = base + region_len;
            let stop = end.min(region_end);
            let first = pos - base; // first wanted offset inside the region
            for c in 0..skip {
                // First offset ≥ `first` in plane c.
                let r0 = if first <= c {
                    c
                } else {
                    c + (first - c).div_ceil(skip) * skip
                };
                let mut offset = r0;
                let mut idx = base + self.plane_start(region_len, c) + r0 / skip;
                while base + offset < stop {
                    if let Some(&b) = planar.get(idx) {
                        put(base + offset - start, b);
                    }
                    offset += skip;
                    idx += 1;
                }
            }
            pos = stop;
        }
    }
}

/// MSB-first bit reader over the DDS stream. Reads past the end return zeros, as
/// libmini's `DDS_loadbits`/`DDS_readbits` pad the stream with zero words.
pub(super) struct BitReader<'a> {
    pub(super) bytes: &'a [u8],
    /// Bit position of the next read.
    pub(super) pos: u64,
}

impl<'a> BitReader<'a> {
    pub(super) fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, pos: 0 }
    }

    pub(super) fn end(&self) -> u64 {
        self.bytes.len() as u64 * 8
    }

    pub(super) fn past_end(&self) -> bool {
        self.pos > self.end()
    }

    /// The next `n ≤ 16` bits as an unsigned number.
    #[inline]
    pub(super) fn read(&mut self, n: u32) -> u32 {
        debug_assert!(n <= 16);
        let byte = usize::try_from(self.pos >> 3).unwrap_or(usize::MAX);
        let at = |i: usize| u32::from(self.bytes.get(byte.saturating_add(i)).copied().unwrap_or(0));
        let window = (at(0) << 16) | (at(1) << 8) | at(2);
        let shift = 24 - (self.pos & 7) as u32 - n;
        self.pos += u64::from(n);
        (window >> shift) & ((1u32 << n) - 1)
    }

    pub(super) fn skip(&mut self, n: u64) {
        self.pos = self.pos.saturating_add(n);
    }
}

/// The 18-bit header of a DDS stream (the first two reads of libmini `DDS_decode`).
#[derive(Debug, Clone, Copy)]
pub(super) struct DdsParams {
    /// Number of byte planes (1‥4).
    pub(super) skip: usize,
    /// Row length used by the 2-D predictor (1‥65536; 1 disables it).
    pub(super) strip: usize,
}

pub(super) fn read_dds_params(reader: &mut BitReader<'_>) -> Result<DdsParams, PvmError> {
    let skip = reader.read(2) as usize + 1;
    let strip = reader.read(16) as usize + 1;
    if reader.past_end() {
        return Err(PvmError::CorruptDds(format!(
            "{} bytes are too short for the 18-bit stream header",
            reader.bytes.len()
        )));
    }
    Ok(DdsParams { skip, strip })
}

/// Width in bits of a run's values from its 3-bit code (libmini `DDS_decode(int)`):
/// 0 → 0, k → k + 1, so widths are 0, 2, 3, …, 8.
fn value_width(code: u32) -> u32 {
    if code == 0 { 0 } else { code + 1 }
}

/// The error for a run that reaches past the end of the data (a truncated file, mostly).
fn overrun(reader: &BitReader<'_>, run_start: u64) -> PvmError {
    PvmError::CorruptDds(format!(
        "the data ends inside a run (bits {run_start}‥{} needed, {} present; the file is probably truncated)",
        reader.pos,
        reader.end()
    ))
}

/// First pass over a DDS stream: how many bytes it decodes to, storing nothing. Each
/// run consumes at least 10 bits, and a run reaching past the data is an error, so
/// this ends after at most `stream.len() · 8 / 10` runs.
pub(super) fn dds_decoded_len(stream: &[u8]) -> Result<(DdsParams, u64), PvmError> {
    let mut reader = BitReader::new(stream);
    let params = read_dds_params(&mut reader)?;
    let mut total = 0u64;
    loop {
        let run_start = reader.pos;
        let count = reader.read(DDS_RUN_BITS);
        if count == 0 {
            break;
        }
        let width = value_width(reader.read(3));
        reader.skip(u64::from(count) * u64::from(width));
        if reader.past_end() {
            return Err(overrun(&reader, run_start));
        }
        total += u64::from(count);
    }
    Ok((params, total))
}

/// Decodes the stream's bytes in planar order (libmini `DDS_decode` minus the final
/// `DDS_interleave`), handing each to `sink` with its index; stops early when `sink`
/// returns `false`. The 2-D predictor looks back `strip + 1` bytes, so a ring buffer
/// of the recent output suffices and the caller decides what to keep.
pub(super) fn dds_decode_with(
    stream: &[u8],
    mut sink: impl FnMut(usize, u8) -> bool,
) -> Result<(), PvmError> {
    const RING: usize = 1 << 17; // > 65536 + 1, the largest look-back
    const MASK: usize = RING - 1;
    let mut ring = vec![0u8; RING];
    let mut reader = BitReader::new(stream);
    let params = read_dds_params(&mut reader)?;
    let strip = params.strip;
    let mut i = 0usize; // index of the next output byte
    let mut act: i32 = 0; // previous output byte
    loop {
        let run_start = reader.pos;
        let count = reader.read(DDS_RUN_BITS);
        if count == 0 {
            return Ok(());
        }
        let width = value_width(reader.read(3));
        let half = (1i32 << width) >> 1;
        for _ in 0..count {
            let delta = reader.read(width) as i32 - half;
            let predicted = if strip > 1 && i > strip {
                let a = ring.get((i - strip) & MASK).copied().unwrap_or(0);
                let b = ring.get((i - strip - 1) & MASK).copied().unwrap_or(0);
                i32::from(a) - i32::from(b)
            } else {
                0
            };
            act = (act + predicted + delta).rem_euclid(256);
            let byte = act as u8;
            if let Some(slot) = ring.get_mut(i & MASK) {
                *slot = byte;
            }
            if !sink(i, byte) {
                return Ok(());
            }
            i += 1;
        }
        if reader.past_end() {
            return Err(overrun(&reader, run_start));
        }
    }
}
