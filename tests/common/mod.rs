//! Shared helpers for integration tests.
#![allow(
    dead_code,
    reason = "each test binary uses a different subset of these helpers"
)]

use std::path::PathBuf;

/// The shared real volumes (`../shared/data` beside the checkout, or `$VOLAO_DATA`).
/// Missing data is a failure with instructions, never a silent skip.
pub fn data_dir() -> PathBuf {
    let dir = std::env::var_os("VOLAO_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    assert!(
        dir.join("README.md").is_file(),
        "test data not found at {}: the tests read the real volumes from ../shared/data \
         (or set VOLAO_DATA to that folder); see README.md, 'Test data'",
        dir.display()
    );
    dir
}

pub fn data(rel: &str) -> PathBuf {
    let p = data_dir().join(rel);
    assert!(
        p.is_file(),
        "{} is missing from the shared data folder",
        p.display()
    );
    p
}

/// Every loadable file in the shared data folder with the raw flags it needs.
pub fn shared_files() -> Vec<(&'static str, volao::volume::RawOverrides)> {
    use volao::volume::{Endian, RawOverrides, VoxelType};
    let none = RawOverrides::default;
    vec![
        ("nifti/ch2.nii.gz", none()),
        ("nifti/avg152T1_LR_nifti.nii", none()),
        ("nifti/avg152T1_LR_nifti.nii.gz", none()),
        ("nifti/avg152T1_LR_nifti2.nii.gz", none()),
        ("nifti/big.nii.gz", none()),
        ("nifti/little.nii.gz", none()),
        ("nifti/with_extension.nii.gz", none()),
        ("pvm/Bucky.pvm", none()),
        ("pvm/Lobster.pvm", none()),
        ("pvm/Storm-t01.pvm", none()),
        ("pvm/Storm-t11.pvm", none()),
        ("raw/engine.raw", none()),
        ("raw/hydrogenatom.raw", none()),
        (
            "raw/cranium-ct.raw",
            RawOverrides {
                dims: Some([256, 256, 108]),
                ty: Some(VoxelType::I16),
                endian: Some(Endian::Little),
                spacing: Some([0.957031, 0.957031, 1.5]),
                offset: None,
            },
        ),
    ]
}

/// Tiny deterministic PRNG (xorshift64*), so mutation tests are reproducible.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}
