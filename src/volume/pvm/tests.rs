//! PVM and DDS round trips, mutations and golden bit streams.
#![allow(clippy::unwrap_used)]

use super::dds::*;
use super::*;

/// The first bytes of the Volume Library's Bucky.pvm (DDS v3d, skip 1, strip 32),
/// as written by libmini's encoder: a golden sample of the real bit stream.
const BUCKY_PREFIX: [u8; 56] = [
    0x44, 0x44, 0x53, 0x20, 0x76, 0x33, 0x64, 0x0a, 0x00, 0x07, 0xcb, 0xfd, 0x08, 0x67, 0x76, 0x65,
    0x7a, 0x97, 0xf6, 0xe9, 0x37, 0xf6, 0xe9, 0x37, 0xf5, 0x8a, 0x76, 0xf9, 0x16, 0xf9, 0x15, 0x9a,
    0x75, 0x97, 0x72, 0x1a, 0x04, 0x08, 0x10, 0x61, 0x45, 0x9b, 0x73, 0x56, 0x05, 0x29, 0x23, 0xe8,
    0x5b, 0xd0, 0x87, 0xf0, 0x48, 0x6a, 0xca, 0x28,
];

/// Tiny xorshift64 PRNG so the tests need no crates.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

/// MSB-first bit writer for the test encoder.
#[derive(Default)]
struct BitWriter {
    bytes: Vec<u8>,
    acc: u64,
    bits: u32,
}

impl BitWriter {
    fn put(&mut self, value: u32, n: u32) {
        for k in (0..n).rev() {
            self.acc = (self.acc << 1) | u64::from((value >> k) & 1);
            self.bits += 1;
            if self.bits == 8 {
                self.bytes.push(self.acc as u8);
                self.acc = 0;
                self.bits = 0;
            }
        }
    }

    fn finish(mut self) -> Vec<u8> {
        if self.bits > 0 {
            self.bytes.push((self.acc << (8 - self.bits)) as u8);
        }
        self.bytes
    }
}

/// A simple but valid DDS encoder (not libmini's run merging): split into planes as
/// `DDS_deinterleave` does, predict, and emit runs of ≤ 127 values at the widest
/// width any of them needs. `block_elems` 0 = v3d layout. `terminator` writes an
/// explicit zero count (libmini relies on the zero padding instead).
fn dds_encode(
    data: &[u8],
    skip: usize,
    strip: usize,
    block_elems: usize,
    terminator: bool,
) -> Vec<u8> {
    let planes = Planes {
        skip,
        block_bytes: if block_elems == 0 {
            0
        } else {
            block_elems * skip
        },
        len: data.len(),
    };
    let mut planar = vec![0u8; data.len()];
    for (pos, &b) in data.iter().enumerate() {
        planar[planes.index(pos)] = b;
    }
    let mut deltas = Vec::with_capacity(planar.len());
    let mut prev = 0i32;
    for i in 0..planar.len() {
        let pred = if strip > 1 && i > strip {
            i32::from(planar[i - strip]) - i32::from(planar[i - strip - 1])
        } else {
            0
        };
        let d = (i32::from(planar[i]) - prev - pred).rem_euclid(256);
        deltas.push(if d > 127 { d - 256 } else { d });
        prev = i32::from(planar[i]);
    }
    let width_of = |d: i32| -> u32 {
        if d == 0 {
            return 0;
        }
        (2..=8)
            .find(|&w| -(1 << w) / 2 <= d && d < (1 << w) / 2)
            .unwrap()
    };
    let mut w = BitWriter::default();
    w.put(skip as u32 - 1, 2);
    w.put(strip as u32 - 1, 16);
    for run in deltas.chunks(127) {
        let width = run.iter().map(|&d| width_of(d)).max().unwrap();
        w.put(run.len() as u32, 7);
        w.put(if width == 0 { 0 } else { width - 1 }, 3);
        for &d in run {
            w.put((d + (1 << width) / 2) as u32, width);
        }
    }
    if terminator {
        w.put(0, 7);
    }
    w.finish()
}

fn with_magic(magic: &[u8], stream: &[u8]) -> Vec<u8> {
    [magic, stream].concat()
}

fn write_to_vec(
    dims: [usize; 3],
    spacing: [f32; 3],
    voxels: &PvmVoxels,
    descriptions: &[(String, String)],
) -> Vec<u8> {
    let mut out = Vec::new();
    write_pvm3(&mut out, dims, spacing, voxels.samples(), descriptions).unwrap();
    out
}

fn descs(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
    pairs
        .iter()
        .map(|(l, t)| (l.to_string(), t.to_string()))
        .collect()
}

const MB: u64 = 1 << 20;

#[test]
fn roundtrip_u8_odd_dims() {
    let dims = [3, 5, 7];
    let voxels = PvmVoxels::U8((0..105u32).map(|i| (i * 37 % 256) as u8).collect());
    let d = descs(&[
        ("description", "Test volume"),
        ("courtesy", "nobody"),
        ("parameter", "x=1"),
        ("comment", "multi\nline ünïcode"),
    ]);
    let bytes = write_to_vec(dims, [1.0, 0.5, 1.4], &voxels, &d);
    assert!(bytes.starts_with(b"PVM3\n3 5 7\n1 0.5 1.4\n1\n"));
    let v = read_pvm(&bytes, MB).unwrap();
    assert_eq!(v.dims, dims);
    assert_eq!(v.spacing, Some([1.0, 0.5, 1.4]));
    assert_eq!(v.voxels, voxels);
    assert_eq!(v.descriptions, d);
    assert_eq!(v.version, PvmVersion::Pvm3);
    assert_eq!(v.compression, None);
}

#[test]
fn roundtrip_u16_big_endian() {
    let dims = [3, 5, 7];
    let mut values: Vec<u16> = (0..105u32).map(|i| (i * 2477 % 65536) as u16).collect();
    values[0] = 0x1234;
    values[1] = 0xffff;
    values[2] = 0;
    let voxels = PvmVoxels::U16(values);
    let d = descs(&[("courtesy", "c"), ("comment", "")]);
    let bytes = write_to_vec(dims, [0.1, 3.333_333_3, 1e-7], &voxels, &d);
    let header = b"PVM3\n3 5 7\n0.1 3.3333333 0.0000001\n2\n";
    assert!(bytes.starts_with(header), "{:?}", show(&bytes));
    assert_eq!(
        &bytes[header.len()..header.len() + 4],
        &[0x12, 0x34, 0xff, 0xff]
    );
    assert!(bytes.ends_with(b"\0c\0\0\0"));
    let v = read_pvm(&bytes, MB).unwrap();
    assert_eq!(v.voxels, voxels);
    assert_eq!(v.spacing, Some([0.1, 3.333_333_3, 1e-7]));
    assert_eq!(v.descriptions, descs(&[("courtesy", "c")]));
}

#[test]
fn writer_merges_unknown_labels_and_rejects_bad_input() {
    let voxels = PvmVoxels::U8(vec![1, 2]);
    let d = descs(&[("descrip", "from nifti"), ("Comment", "hello")]);
    let v = read_pvm(&write_to_vec([2, 1, 1], [1.0; 3], &voxels, &d), MB).unwrap();
    assert_eq!(
        v.descriptions,
        descs(&[("comment", "descrip: from nifti\nhello")])
    );

    let mut sink = Vec::new();
    assert!(write_pvm3(&mut sink, [0, 1, 2], [1.0; 3], voxels.samples(), &[]).is_err());
    assert!(write_pvm3(&mut sink, [3, 1, 1], [1.0; 3], voxels.samples(), &[]).is_err());
    assert!(write_pvm3(&mut sink, [2, 1, 1], [0.0, 1.0, 1.0], voxels.samples(), &[]).is_err());
    assert!(
        write_pvm3(
            &mut sink,
            [2, 1, 1],
            [f32::NAN, 1.0, 1.0],
            voxels.samples(),
            &[]
        )
        .is_err()
    );
    let nul = descs(&[("comment", "a\0b")]);
    assert!(write_pvm3(&mut sink, [2, 1, 1], [1.0; 3], voxels.samples(), &nul).is_err());
}

#[test]
fn plain_pvm1_with_comments() {
    let bytes = b"PVM\n# a comment\n#another\n2 2 1\n1\n\x01\x02\x03\x04";
    let v = read_pvm(bytes, MB).unwrap();
    assert_eq!(v.version, PvmVersion::Pvm1);
    assert_eq!(v.dims, [2, 2, 1]);
    assert_eq!(v.spacing, None);
    assert_eq!(v.voxels, PvmVoxels::U8(vec![1, 2, 3, 4]));
    assert!(v.descriptions.is_empty());
}

#[test]
fn pvm2_sixteen_bit() {
    let bytes = b"PVM2\n2 1 1\n0.5 1 2\n2\n\x01\x02\xff\xfe";
    let v = read_pvm(bytes, MB).unwrap();
    assert_eq!(v.version, PvmVersion::Pvm2);
    assert_eq!(v.spacing, Some([0.5, 1.0, 2.0]));
    assert_eq!(v.voxels, PvmVoxels::U16(vec![0x0102, 0xfffe]));
    // CRLF line ends are tolerated.
    let crlf = b"PVM2\r\n2 1 1\r\n0.5 1 2\r\n2\r\n\x01\x02\xff\xfe";
    assert_eq!(read_pvm(crlf, MB).unwrap().voxels, v.voxels);
}

#[test]
fn header_errors() {
    let err = |b: &[u8]| read_pvm(b, MB).unwrap_err();
    assert!(matches!(err(b"GIF89a"), PvmError::NotPvm { .. }));
    assert!(matches!(
        err(b"PVMS\n1 1 1\n1\n\0"),
        PvmError::UnsupportedVariant(_)
    ));
    assert!(matches!(err(b"PVM\n0 2 2\n1\n"), PvmError::ZeroDims { .. }));
    assert!(matches!(
        err(b"PVM\n2 2 2\n3\n12345678"),
        PvmError::UnsupportedComponents(3)
    ));
    assert!(matches!(
        err(b"PVM\n2 2 2\n0\n"),
        PvmError::UnsupportedComponents(0)
    ));
    assert!(matches!(err(b"PVM\n2 -2 2\n1\n"), PvmError::BadHeader(_)));
    assert!(matches!(err(b"PVM\n2 2\n1\n"), PvmError::BadHeader(_)));
    assert!(matches!(err(b"PVM\n2 2 2 2\n1\n"), PvmError::BadHeader(_)));
    assert!(matches!(
        err(b"PVM\n9999999999 2 2\n1\n"),
        PvmError::BadHeader(_)
    ));
    for spacing in ["0 1 1", "1 -1 1", "nan 1 1", "1 inf 1", "1 1 1e39"] {
        let b = format!("PVM2\n1 1 1\n{spacing}\n1\n\x07");
        assert!(
            matches!(err(b.as_bytes()), PvmError::BadSpacing { .. }),
            "{spacing}"
        );
    }
    assert!(matches!(
        err(b"PVM\n1 1 1\n1\n\x07\x08"),
        PvmError::TrailingBytes { count: 1, .. }
    ));
    assert!(matches!(
        err(b"PVM3\n1 1 1\n1 1 1\n1\n\x07a\0b\0c\0"),
        PvmError::TruncatedStrings(_)
    ));
    assert!(matches!(
        err(b"PVM3\n1 1 1\n1 1 1\n1\n\x07\0\0\0\0x"),
        PvmError::TrailingBytes { .. }
    ));
}

#[test]
fn truncation_is_an_error_with_sizes() {
    let voxels = PvmVoxels::U8(vec![9; 105]);
    let full = write_to_vec([3, 5, 7], [1.0; 3], &voxels, &descs(&[("comment", "x")]));
    for cut in 0..full.len() {
        assert!(
            read_pvm(&full[..cut], MB).is_err(),
            "prefix of {cut} bytes was accepted"
        );
    }
    let header_len = b"PVM3\n3 5 7\n1 1 1\n1\n".len();
    let msg = read_pvm(&full[..header_len + 50], MB)
        .unwrap_err()
        .to_string();
    assert_eq!(
        msg,
        "truncated: header says 3×5×7 × 1 byte = 105 bytes of voxels but only 50 follow"
    );
    let msg = read_pvm(b"PVM3\n3 5 7\n1 1", MB).unwrap_err().to_string();
    assert!(msg.starts_with("truncated:"), "{msg}");
}

#[test]
fn absurd_dims_refused_without_allocating() {
    let mut b = b"PVM3\n65535 65535 65535\n1 1 1\n2\n".to_vec();
    b.extend_from_slice(&[0; 100]);
    let e = read_pvm(&b, MB).unwrap_err();
    assert!(
        matches!(
            e,
            PvmError::Truncated {
                expected: 562_924_184_010_750,
                ..
            }
        ),
        "{e}"
    );
    // A complete file that is merely over the caller's limit.
    let ok = write_to_vec([3, 5, 7], [1.0; 3], &PvmVoxels::U8(vec![0; 105]), &[]);
    assert!(matches!(
        read_pvm(&ok, 104),
        Err(PvmError::TooLarge {
            bytes: 105,
            limit: 104,
            ..
        })
    ));
    assert!(read_pvm(&ok, 105).is_ok());
    // A DDS stream whose header claims absurd dims: refused from the header alone.
    let mut absurd = b"PVM3\n65535 65535 65535\n1 1 1\n2\n".to_vec();
    absurd.extend_from_slice(&[0; 64]);
    let e = read_pvm(
        &with_magic(DDS_V3D_MAGIC, &dds_encode(&absurd, 1, 1, 0, true)),
        MB,
    )
    .unwrap_err();
    assert!(matches!(e, PvmError::Truncated { .. }), "{e}");
}

#[test]
fn dds_stream_over_the_limit_is_refused_before_decoding() {
    // 2 MiB of zeros compresses to a few KiB; with a 1 KiB cap it must be refused.
    let dims = [128, 128, 128];
    let file = write_to_vec(
        dims,
        [1.0; 3],
        &PvmVoxels::U8(vec![0; 128 * 128 * 128]),
        &[],
    );
    for skip in [1, 2] {
        let dds = with_magic(DDS_V3D_MAGIC, &dds_encode(&file, skip, 128, 0, false));
        let e = read_pvm(&dds, 1024).unwrap_err();
        assert!(
            matches!(
                e,
                PvmError::TooLarge {
                    bytes: 2_097_152,
                    limit: 1024,
                    ..
                }
            ),
            "{e}"
        );
    }
    // Garbage that decodes to a long non-PVM stream: counted, never stored.
    let ones = with_magic(DDS_V3D_MAGIC, &vec![0xff; 1 << 16]);
    assert!(read_pvm(&ones, 1024).is_err());
}

#[test]
fn golden_prefix_of_a_real_file_decodes_to_its_header() {
    let stream = &BUCKY_PREFIX[DDS_V3D_MAGIC.len()..];
    let mut reader = BitReader::new(stream);
    let params = read_dds_params(&mut reader).unwrap();
    assert_eq!((params.skip, params.strip), (1, 32));
    let planes = Planes {
        skip: 1,
        block_bytes: 0,
        len: 22,
    };
    let header = dds_peek(stream, planes, 22).unwrap().unwrap();
    assert_eq!(header, b"PVM3\n32 32 32\n1 1 1\n1\n");
    // The prefix alone is a truncated stream: an error, not a panic.
    assert!(matches!(
        read_pvm(&BUCKY_PREFIX, MB),
        Err(PvmError::CorruptDds(_))
    ));
}

fn sample_file(two_bytes: bool) -> (Vec<u8>, PvmVoxels) {
    let dims = [13, 6, 5];
    let n = 13 * 6 * 5;
    let voxels = if two_bytes {
        PvmVoxels::U16(
            (0..n as u32)
                .map(|i| ((i * i * 97 + i * 13) % 65536) as u16)
                .collect(),
        )
    } else {
        PvmVoxels::U8(
            (0..n as u32)
                .map(|i| ((i % 13) * 11 + (i / 78) * 7) as u8)
                .collect(),
        )
    };
    let d = descs(&[("description", "sample"), ("parameter", "p")]);
    (write_to_vec(dims, [1.0, 2.0, 3.0], &voxels, &d), voxels)
}

#[test]
fn dds_v3d_roundtrips_through_our_encoder() {
    for two in [false, true] {
        let (file, voxels) = sample_file(two);
        for skip in [1, 2, 3, 4] {
            for strip in [1, 2, 13, 26] {
                for terminator in [false, true] {
                    let dds = with_magic(
                        DDS_V3D_MAGIC,
                        &dds_encode(&file, skip, strip, 0, terminator),
                    );
                    let v = read_pvm(&dds, MB).unwrap();
                    assert_eq!(v.voxels, voxels, "skip {skip} strip {strip}");
                    assert_eq!(v.compression, Some(DdsVersion::V3d));
                    assert_eq!(
                        v.descriptions,
                        descs(&[("description", "sample"), ("parameter", "p")])
                    );
                }
            }
        }
    }
}

#[test]
fn dds_v3e_blocks_with_a_small_block_size() {
    // The real v3e block is skip × 2^24 bytes; the layout logic is the same for any
    // block, so test it with tiny blocks that split the file into many regions.
    for two in [false, true] {
        let (file, voxels) = sample_file(two);
        for skip in [1, 2, 3] {
            for block in [1, 7, 64, 1000] {
                let stream = dds_encode(&file, skip, 13, block, false);
                let source = decompress_dds(&stream, block, MB).unwrap();
                let v = parse_pvm(source, Some(DdsVersion::V3e), MB).unwrap();
                assert_eq!(v.voxels, voxels, "skip {skip} block {block}");
            }
        }
        // And through the public entry point with the real block size.
        let dds = with_magic(
            DDS_V3E_MAGIC,
            &dds_encode(&file, 2, 13, V3E_INTERLEAVE_BLOCK, false),
        );
        let v = read_pvm(&dds, MB).unwrap();
        assert_eq!((v.voxels, v.compression), (voxels, Some(DdsVersion::V3e)));
    }
}

#[test]
fn planes_gather_matches_index() {
    let mut rng = XorShift(7);
    for _ in 0..200 {
        let len = rng.below(300) + 1;
        let skip = rng.below(4) + 1;
        let block_bytes = if rng.below(2) == 0 {
            0
        } else {
            (rng.below(40) + 1) * skip
        };
        let planes = Planes {
            skip,
            block_bytes,
            len,
        };
        let planar: Vec<u8> = (0..len).map(|i| (i % 251) as u8).collect();
        let start = rng.below(len);
        let end = start + rng.below(len - start + 1);
        let mut got = vec![None; end - start];
        planes.gather(&planar, start, end, |i, b| got[i] = Some(b));
        for (k, g) in got.iter().enumerate() {
            assert_eq!(*g, Some(planar[planes.index(start + k)]));
        }
        let mut seen = vec![false; len];
        for pos in 0..len {
            seen[planes.index(pos)] = true;
        }
        assert!(seen.iter().all(|&s| s), "index is not a permutation");
    }
}

fn mutate(rng: &mut XorShift, base: &[u8]) -> Vec<u8> {
    let mut m = base.to_vec();
    for _ in 0..=rng.below(3) {
        match rng.below(6) {
            0 => m.truncate(rng.below(m.len() + 1)),
            1 => {
                let i = rng.below(m.len());
                if let Some(b) = m.get_mut(i) {
                    *b ^= 1 << rng.below(8);
                }
            }
            2 => {
                let i = rng.below(m.len());
                if let Some(b) = m.get_mut(i) {
                    *b = rng.next() as u8;
                }
            }
            3 => {
                let i = rng.below(m.len() + 1);
                let pick = b"0123456789 \n#-.e\0\xff";
                m.insert(i, pick[rng.below(pick.len())]);
            }
            4 => {
                if !m.is_empty() {
                    m.remove(rng.below(m.len()));
                }
            }
            _ => {
                let i = rng.below(m.len() + 1);
                m.extend_from_within(..i);
            }
        }
    }
    m
}

#[test]
fn random_mutations_never_panic() {
    let (plain8, _) = sample_file(false);
    let (plain16, _) = sample_file(true);
    let corpus = vec![
        plain8.clone(),
        plain16.clone(),
        b"PVM\n# c\n2 2 1\n1\n\x01\x02\x03\x04".to_vec(),
        b"PVM2\n2 1 1\n0.5 1 2\n2\n\x01\x02\xff\xfe".to_vec(),
        BUCKY_PREFIX.to_vec(),
        with_magic(DDS_V3D_MAGIC, &dds_encode(&plain8, 1, 13, 0, false)),
        with_magic(DDS_V3D_MAGIC, &dds_encode(&plain16, 2, 13, 0, false)),
        with_magic(
            DDS_V3E_MAGIC,
            &dds_encode(&plain16, 2, 1, V3E_INTERLEAVE_BLOCK, true),
        ),
        with_magic(DDS_V3D_MAGIC, &dds_encode(&plain8, 3, 2, 0, true)),
    ];
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let mut accepted = 0;
    for round in 0..2400 {
        let base = &corpus[round % corpus.len()];
        let m = mutate(&mut rng, base);
        let limit = if rng.below(4) == 0 {
            rng.below(4096) as u64
        } else {
            MB
        };
        if let Ok(v) = read_pvm(&m, limit) {
            accepted += 1;
            assert_eq!(v.voxels.len(), v.dims.iter().product::<usize>());
            assert!(v.voxels.len() * v.voxels.bytes_per_voxel() <= limit as usize);
        }
    }
    assert!(
        accepted > 0,
        "no mutation survived; the corpus is not exercising the happy path"
    );
}
