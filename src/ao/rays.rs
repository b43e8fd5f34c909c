//! Ray directions for Local Ambient Occlusion (CAO paper §4; Hernell et al.'s LAO).
//!
//! LAO casts K rays from every voxel and averages their ambient values (Eq. 3 of the
//! CAO paper). The paper's patterns come from the 26-neighbourhood of a voxel — 6, 14,
//! 26 and 54 rays, "with a jittering factor added to increase the randomness" — and
//! its ground truth (Tables 5–6) uses 512 rays on a spherical Fibonacci lattice
//! (Keinert et al. 2015). Everything here is deterministic: the same set gives the same
//! directions on every machine, so the GPU stage and its CPU twin can share them.

use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

use glam::{DQuat, DVec3, IVec3, Vec3};

/// Largest Fibonacci lattice [`RaySet::parse`] accepts (and [`RaySet::validate`] allows).
pub const MAX_FIBONACCI_RAYS: usize = 65_536;

/// What [`RaySet::parse`] accepts, for error messages.
const VALID_NAMES: &str =
    "\"6\", \"14\", \"26\", \"54\", \"fib:N\" or \"fibonacci:N\" (N from 1 to 65536)";

/// Jitter, step 1: each antipodal pair of rays is tilted by at most this angle.
const TILT_DEGREES: f64 = 3.0;
/// Jitter, step 2: the whole pattern is then rotated by this angle…
const ROTATION_DEGREES: f64 = 5.0;
/// …about this skew axis (normalised before use), so no ray stays on a voxel axis.
const ROTATION_AXIS: [f64; 3] = [1.0, 2.0, 3.0];

/// A set of LAO ray directions: one of the paper's patterns or a Fibonacci lattice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum RaySet {
    /// 6 rays: Manhattan distance 1 (±x, ±y, ±z).
    Six,
    /// 14 rays: Manhattan distance 1 and 3 (the 6 faces and 8 corners of a voxel).
    Fourteen,
    /// 26 rays: every neighbour in the 26-neighbourhood of a voxel.
    TwentySix,
    /// 54 rays: the centres of the 54 facelets of a Rubik's cube.
    FiftyFour,
    /// N rays on a spherical Fibonacci lattice (Keinert et al. 2015); N in 1..=65536.
    Fibonacci(usize),
}

/// Why a ray set name or a set of ray weights was refused.
#[derive(Debug, thiserror::Error)]
pub enum RayError {
    /// The name is none of the known patterns.
    #[error("unknown ray set {name:?}: expected one of {}", VALID_NAMES)]
    UnknownName {
        /// The name as given.
        name: String,
    },
    /// A Fibonacci set whose ray count is not a whole number in 1..=65536.
    #[error(
        "bad Fibonacci ray count {count:?} in {name:?}: expected a whole number from 1 to \
         65536, e.g. \"fib:512\""
    )]
    FibonacciCount {
        /// The whole name as given.
        name: String,
        /// The count part of it.
        count: String,
    },
    /// No weights at all.
    #[error("no ray weights given: pass one finite, non-negative weight per ray")]
    NoWeights,
    /// A weight that is negative, NaN or infinite.
    #[error("ray weight {index} is {value}: weights must be finite and non-negative")]
    BadWeight {
        /// Index of the first offending weight.
        index: usize,
        /// Its value.
        value: f32,
    },
    /// Every weight is zero, so no ray would count.
    #[error(
        "all {count} ray weights are zero: at least one ray must count (uniform weights give \
         plain LAO)"
    )]
    AllZeroWeights {
        /// How many weights were given.
        count: usize,
    },
}

impl RaySet {
    /// Ground truth of the paper's Tables 5–6.
    pub const GROUND_TRUTH: RaySet = RaySet::Fibonacci(512);

    /// The paper's four patterns, smallest first.
    pub const PAPER: [RaySet; 4] = [
        RaySet::Six,
        RaySet::Fourteen,
        RaySet::TwentySix,
        RaySet::FiftyFour,
    ];

    /// Parses "6", "14", "26", "54" (the paper's patterns) or "fib:N" / "fibonacci:N" (a Fibonacci lattice of N rays).
    pub fn parse(s: &str) -> Result<RaySet, RayError> {
        let name = s.trim();
        match name {
            "6" => return Ok(RaySet::Six),
            "14" => return Ok(RaySet::Fourteen),
            "26" => return Ok(RaySet::TwentySix),
            "54" => return Ok(RaySet::FiftyFour),
            _ => {}
        }
        let lower = name.to_ascii_lowercase();
        let Some(count) = lower
            .strip_prefix("fib:")
            .or_else(|| lower.strip_prefix("fibonacci:"))
        else {
            return Err(RayError::UnknownName { name: s.to_owned() });
        };
        match count.trim().parse::<usize>() {
            Ok(n) if (1..=MAX_FIBONACCI_RAYS).contains(&n) => Ok(RaySet::Fibonacci(n)),
            _ => Err(RayError::FibonacciCount {
                name: s.to_owned(),
                count: count.to_owned(),
            }),
        }
    }

    /// Returns the set if it is usable: a Fibonacci count must lie in 1..=65536.
    ///
    /// [`RaySet::parse`] already checks this; call it on sets built directly or deserialised.
    pub fn validate(self) -> Result<RaySet, RayError> {
        match self {
            RaySet::Fibonacci(n) if !(1..=MAX_FIBONACCI_RAYS).contains(&n) => {
                Err(RayError::FibonacciCount {
                    name: self.name(),
                    count: n.to_string(),
                })
            }
            _ => Ok(self),
        }
    }

    /// The name [`RaySet::parse`] reads back: "6", "14", "26", "54" or "fib:N".
    pub fn name(&self) -> String {
        match self {
            RaySet::Six => "6".to_owned(),
            RaySet::Fourteen => "14".to_owned(),
            RaySet::TwentySix => "26".to_owned(),
            RaySet::FiftyFour => "54".to_owned(),
            RaySet::Fibonacci(n) => format!("fib:{n}"),
        }
    }

    /// Number of rays, K in Eq. 3.
    pub fn count(&self) -> usize {
        match self {
            RaySet::Six => 6,
            RaySet::Fourteen => 14,
            RaySet::TwentySix => 26,
            RaySet::FiftyFour => 54,
            RaySet::Fibonacci(n) => *n,
        }
    }

    /// Unit directions (f32). The paper patterns carry the small fixed jitter (see below); Fibonacci sets do not need any.
    ///
    /// The jitter is fixed, so every voxel and every run uses the same rays:
    /// 1. each antipodal pair {p, −p} of the integer lattice pattern is tilted by up to
    ///    3° (angle = 3° · u₂, azimuth = 2π · u₁ in a tangent frame of the pair's
    ///    canonical member, u₁ and u₂ from a 32-bit integer hash of its lattice
    ///    coordinates); −p gets exactly the negated direction, so the pattern stays
    ///    antipodal and its mean direction stays 0;
    /// 2. the whole pattern is rotated by 5° about the skew axis (1, 2, 3)/√14, so no
    ///    ray runs along a voxel row even where the tilt happens to be tiny.
    ///
    /// Every ray thus lies within 8° of its lattice direction, and the ray order is that of
    /// [`RaySet::unjittered`].
    pub fn directions(&self) -> Vec<Vec3> {
        match self.lattice() {
            Some(points) => points.into_iter().map(jittered).collect(),
            None => fibonacci(self.count()),
        }
    }

    /// The same pattern without jitter (for tests and for users who want exact lattice directions).
    pub fn unjittered(&self) -> Vec<Vec3> {
        match self.lattice() {
            Some(points) => points
                .into_iter()
                .map(|p| p.as_dvec3().normalize().as_vec3())
                .collect(),
            None => fibonacci(self.count()),
        }
    }

    /// Integer lattice points of the paper's patterns (in ray order); `None` for Fibonacci.
    fn lattice(&self) -> Option<Vec<IVec3>> {
        let neighbours = |keep: fn(i32) -> bool| -> Vec<IVec3> {
            let mut points = Vec::new();
            for x in -1..=1 {
                for y in -1..=1 {
                    for z in -1..=1 {
                        let manhattan = i32::abs(x) + i32::abs(y) + i32::abs(z);
                        if manhattan > 0 && keep(manhattan) {
                            points.push(IVec3::new(x, y, z));
                        }
                    }
                }
            }
            points
        };
        match self {
            RaySet::Six => Some(neighbours(|m| m == 1)),
            RaySet::Fourteen => Some(neighbours(|m| m == 1 || m == 3)),
            RaySet::TwentySix => Some(neighbours(|_| true)),
            RaySet::FiftyFour => {
                // A Rubik's cube of side 3 around the origin: facelet centres of face +x
                // are (1.5, a, b), a, b ∈ {−1, 0, 1}; doubled to stay on integers.
                let mut points = Vec::with_capacity(54);
                for axis in 0..3 {
                    for sign in [1, -1] {
                        for a in -1..=1 {
                            for b in -1..=1 {
                                let mut p = IVec3::ZERO;
                                p[axis] = 3 * sign;
                                p[(axis + 1) % 3] = 2 * a;
                                p[(axis + 2) % 3] = 2 * b;
                                points.push(p);
                            }
                        }
                    }
                }
                Some(points)
            }
            RaySet::Fibonacci(_) => None,
        }
    }
}

impl fmt::Display for RaySet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for RaySet {
    type Err = RayError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        RaySet::parse(s)
    }
}

/// Optional per-ray weights w_k of Eq. 3, normalised so their mean is 1 (so the uniform case is all ones).
pub fn uniform_weights(n: usize) -> Vec<f32> {
    vec![1.0; n]
}

/// Scales weights w_k of Eq. 3 so their mean is 1, keeping their proportions.
///
/// Weights must be finite and non-negative, and not all zero.
pub fn normalise_weights(w: &[f32]) -> Result<Vec<f32>, RayError> {
    if w.is_empty() {
        return Err(RayError::NoWeights);
    }
    if let Some((index, &value)) = w
        .iter()
        .enumerate()
        .find(|&(_, v)| !(v.is_finite() && *v >= 0.0))
    {
        return Err(RayError::BadWeight { index, value });
    }
    // Summed in f64: finite f32 weights may overflow an f32 sum.
    let sum: f64 = w.iter().map(|&v| f64::from(v)).sum();
    if sum <= 0.0 {
        return Err(RayError::AllZeroWeights { count: w.len() });
    }
    let scale = w.len() as f64 / sum;
    Ok(w.iter().map(|&v| (f64::from(v) * scale) as f32).collect())
}

/// N points of the spherical Fibonacci lattice (Keinert et al. 2015):
/// z_i = 1 − (2i + 1)/N, φ_i = 2π · i/Φ with Φ the golden ratio.
fn fibonacci(n: usize) -> Vec<Vec3> {
    // 1/Φ = Φ − 1; only the fractional part of i/Φ matters for the angle.
    let inv_phi = (5.0_f64.sqrt() - 1.0) / 2.0;
    let nf = n as f64;
    (0..n)
        .map(|i| {
            let i = i as f64;
            let z = 1.0 - (2.0 * i + 1.0) / nf;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = TAU * (i * inv_phi).fract();
            DVec3::new(r * phi.cos(), r * phi.sin(), z)
                .as_vec3()
                .normalize()
        })
        .collect()
}

/// The jittered direction of lattice point `p` (see [`RaySet::directions`]).
fn jittered(p: IVec3) -> Vec3 {
    // The canonical member of {p, −p} has its first non-zero coordinate positive.
    let first = [p.x, p.y, p.z].into_iter().find(|&c| c != 0).unwrap_or(0);
    let canonical = first > 0;
    let q = if canonical { p } else { -p };

    let d = q.as_dvec3().normalize();
    let h1 = hash(lattice_key(q));
    let h2 = hash(h1 ^ 0x9e37_79b9);
    let azimuth = TAU * unit_interval(h1);
    let tilt = TILT_DEGREES.to_radians() * unit_interval(h2);

    // Own tangent frame (not glam's any_orthonormal_pair) so a glam upgrade cannot
    // move the rays.
    let helper = if d.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = d.cross(helper).normalize();
    let e2 = d.cross(e1);
    let tilted = d * tilt.cos() + (e1 * azimuth.cos() + e2 * azimuth.sin()) * tilt.sin();

    let rotation = DQuat::from_axis_angle(
        DVec3::from_array(ROTATION_AXIS).normalize(),
        ROTATION_DEGREES.to_radians(),
    );
    let ray = (rotation * tilted).as_vec3().normalize();
    if canonical { ray } else { -ray }
}

/// Packs a lattice point with coordinates in −3..=3 into a hash key.
fn lattice_key(p: IVec3) -> u32 {
    let c = |v: i32| (v + 8) as u32 & 0xf;
    c(p.x) | c(p.y) << 4 | c(p.z) << 8
}

/// A fixed 32-bit integer hash ("lowbias32", C. Wellons).
fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Maps a hash to [0, 1).
fn unit_interval(h: u32) -> f64 {
    f64::from(h) / 4_294_967_296.0
}

#[cfg(test)]
mod tests {
    use super::*;

    const EPS: f32 = 1e-6;

    fn all_sets() -> Vec<RaySet> {
        let mut sets = RaySet::PAPER.to_vec();
        sets.extend([1, 2, 7, 512].map(RaySet::Fibonacci));
        sets
    }

    fn contains(set: &[Vec3], d: Vec3) -> bool {
        set.iter().any(|s| s.abs_diff_eq(d, EPS))
    }

    fn mean(set: &[Vec3]) -> Vec3 {
        set.iter().sum::<Vec3>() / set.len() as f32
    }

    fn angle_degrees(a: Vec3, b: Vec3) -> f32 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn counts_are_exact() {
        let expected = [6, 14, 26, 54, 1, 2, 7, 512];
        for (set, n) in all_sets().into_iter().zip(expected) {
            assert_eq!(set.count(), n, "{set}");
            assert_eq!(set.directions().len(), n, "{set} jittered");
            assert_eq!(set.unjittered().len(), n, "{set} unjittered");
        }
        assert_eq!(RaySet::GROUND_TRUTH.count(), 512);
    }

    #[test]
    fn directions_are_unit_and_distinct() {
        for set in all_sets() {
            for dirs in [set.directions(), set.unjittered()] {
                for (i, d) in dirs.iter().enumerate() {
                    assert!((d.length() - 1.0).abs() < EPS, "{set} ray {i}: {d}");
                    for (j, e) in dirs.iter().enumerate().skip(i + 1) {
                        assert!(!d.abs_diff_eq(*e, 1e-4), "{set}: rays {i} and {j} are {d}");
                    }
                }
            }
        }
    }

    #[test]
    fn paper_patterns_have_the_right_lattice_directions() {
        let s3 = 3.0_f32.sqrt().recip();
        let six = RaySet::Six.unjittered();
        assert!(six.iter().all(|d| d.abs().max_element() == 1.0));
        let fourteen = RaySet::Fourteen.unjittered();
        assert!(contains(&fourteen, Vec3::new(s3, -s3, s3)));
        assert!(contains(&fourteen, Vec3::NEG_Z));
        let twenty_six = RaySet::TwentySix.unjittered();
        assert!(contains(&twenty_six, Vec3::new(0.0, 1.0, -1.0).normalize()));
        let fifty_four = RaySet::FiftyFour.unjittered();
        for d in [
            Vec3::new(1.5, 0.0, 0.0),
            Vec3::new(1.5, 1.0, -1.0),
            Vec3::new(-1.0, -1.5, 0.0),
            Vec3::new(1.0, 1.0, 1.5),
        ] {
            assert!(contains(&fifty_four, d.normalize()), "{d}");
        }
        // 14 = 6 ∪ corners, 26 ⊃ 14.
        assert!(six.iter().all(|&d| contains(&fourteen, d)));
        assert!(fourteen.iter().all(|&d| contains(&twenty_six, d)));
    }

    #[test]
    fn unjittered_paper_patterns_have_cube_symmetry() {
        let mut symmetries = 0;
        for perm in [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ] {
            for signs in 0..8 {
                symmetries += 1;
                let map = |d: Vec3| {
                    Vec3::from_array(std::array::from_fn(|k| {
                        let s = if signs >> k & 1 == 1 { -1.0 } else { 1.0 };
                        s * d[perm[k]]
                    }))
                };
                for set in RaySet::PAPER {
                    let dirs = set.unjittered();
                    for &d in &dirs {
                        assert!(contains(&dirs, map(d)), "{set}: {d} maps outside");
                    }
                }
            }
        }
        assert_eq!(symmetries, 48);
        for set in RaySet::PAPER {
            let dirs = set.unjittered();
            assert!(mean(&dirs).length() < EPS, "{set}");
            assert!(dirs.iter().all(|&d| contains(&dirs, -d)), "{set}");
        }
    }

    #[test]
    fn jitter_is_small_nonzero_and_balanced() {
        for set in RaySet::PAPER {
            let jittered = set.directions();
            let exact = set.unjittered();
            let mut largest = 0.0_f32;
            for (&j, &e) in jittered.iter().zip(&exact) {
                let angle = angle_degrees(j, e);
                assert!(angle < 10.0, "{set}: {e} moved {angle}°");
                largest = largest.max(angle);
            }
            assert!(largest > 1.0, "{set}: jitter of {largest}° is hardly any");
            // Tilts come in antipodal pairs and the rotation is linear.
            assert!(jittered.iter().all(|&d| contains(&jittered, -d)), "{set}");
            let m = mean(&jittered).length();
            assert!(m < 0.05, "{set}: |mean| = {m}");
            // No ray runs along a voxel row: the nearest is 2.7° off (the 6-set's).
            for d in &jittered {
                let off_axis = d.abs().max_element().min(1.0).acos().to_degrees();
                assert!(
                    off_axis > 2.0,
                    "{set}: {d} is {off_axis}° from a voxel axis"
                );
            }
        }
    }

    #[test]
    fn jitter_is_pinned() {
        // The jitter is part of the output: CPU twin, GPU stage and saved results must
        // agree. If this changes, it changes every LAO image.
        let first = RaySet::Six.directions()[0];
        assert!(
            first.abs_diff_eq(PINNED_SIX_FIRST, 1e-6),
            "first ray of the 6-set is now {first:?}"
        );
        assert_eq!(
            RaySet::FiftyFour.directions(),
            RaySet::FiftyFour.directions()
        );
    }

    /// Jittered direction of the 6-set's first ray, lattice (−1, 0, 0).
    const PINNED_SIX_FIRST: Vec3 = Vec3::new(-0.997_426_45, -0.057_535_56, 0.042_780_556);

    #[test]
    fn fibonacci_is_well_spread() {
        assert_eq!(
            RaySet::Fibonacci(7).directions(),
            RaySet::Fibonacci(7).unjittered()
        );
        for n in [7, 64, 512, 4096] {
            let dirs = RaySet::Fibonacci(n).directions();
            if n >= 512 {
                let m = mean(&dirs).length();
                assert!(m < 1e-3, "fib:{n}: |mean| = {m}");
            }
            let ideal = (4.0 * std::f32::consts::PI / n as f32).sqrt();
            for (i, d) in dirs.iter().enumerate() {
                let nearest = dirs
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, e)| d.distance(*e))
                    .fold(f32::INFINITY, f32::min);
                assert!(
                    nearest < 2.0 * ideal,
                    "fib:{n} point {i}: nearest {nearest}"
                );
                assert!(
                    nearest > 0.5 * ideal,
                    "fib:{n} point {i}: nearest {nearest}"
                );
            }
        }
    }

    #[test]
    fn parse_and_name_round_trip() {
        for set in all_sets().into_iter().chain([RaySet::Fibonacci(65_536)]) {
            let back = RaySet::parse(&set.name()).expect("name parses back");
            assert_eq!(back, set);
            assert_eq!(set.to_string().parse::<RaySet>().expect("FromStr"), set);
        }
        assert_eq!(RaySet::GROUND_TRUTH.name(), "fib:512");
        for (s, set) in [
            ("fibonacci:512", RaySet::Fibonacci(512)),
            (" FIB:12 ", RaySet::Fibonacci(12)),
            ("54", RaySet::FiftyFour),
        ] {
            assert_eq!(RaySet::parse(s).expect("valid name"), set, "{s:?}");
        }
    }

    #[test]
    fn bad_names_are_rejected_with_the_valid_ones() {
        for bad in [
            "",
            "8",
            "six",
            "fib",
            "fib:",
            "fib:0",
            "fib:-3",
            "fib:65537",
            "fib:1.5",
        ] {
            let err = RaySet::parse(bad).expect_err(bad);
            let msg = err.to_string();
            assert!(msg.contains(&format!("{bad:?}")), "{msg}");
            if bad.starts_with("fib:") {
                assert!(matches!(err, RayError::FibonacciCount { .. }), "{bad}");
                assert!(msg.contains("65536"), "{msg}");
            } else {
                for valid in [
                    "\"6\"",
                    "\"14\"",
                    "\"26\"",
                    "\"54\"",
                    "fib:N",
                    "fibonacci:N",
                ] {
                    assert!(msg.contains(valid), "{msg} lacks {valid}");
                }
            }
        }
        assert!(RaySet::Fibonacci(0).validate().is_err());
        assert!(
            RaySet::Fibonacci(MAX_FIBONACCI_RAYS + 1)
                .validate()
                .is_err()
        );
        assert_eq!(RaySet::Six.validate().expect("6 is valid"), RaySet::Six);
    }

    #[test]
    fn uniform_weights_are_ones() {
        assert_eq!(uniform_weights(3), vec![1.0; 3]);
        assert!(uniform_weights(0).is_empty());
        let n = normalise_weights(&uniform_weights(26)).expect("uniform is valid");
        assert_eq!(n, vec![1.0; 26]);
    }

    #[test]
    fn normalise_keeps_proportions_and_mean_one() {
        let w = normalise_weights(&[1.0, 3.0, 0.0, 4.0]).expect("valid weights");
        assert_eq!(w, vec![0.5, 1.5, 0.0, 2.0]);
        let big = normalise_weights(&[f32::MAX, f32::MAX]).expect("no overflow");
        assert_eq!(big, vec![1.0, 1.0]);
        let w = normalise_weights(&[0.1, 0.7, 0.2]).expect("valid weights");
        let mean = w.iter().sum::<f32>() / 3.0;
        assert!((mean - 1.0).abs() < 1e-6, "{mean}");
        assert!((w[1] / w[0] - 7.0).abs() < 1e-5, "{w:?}");
    }

    #[test]
    fn normalise_rejects_bad_weights() {
        for (w, index) in [
            (vec![1.0, -0.5], 1),
            (vec![f32::NAN, 1.0], 0),
            (vec![1.0, 2.0, f32::INFINITY], 2),
        ] {
            match normalise_weights(&w) {
                Err(RayError::BadWeight { index: i, .. }) => assert_eq!(i, index, "{w:?}"),
                other => panic!("{w:?} gave {other:?}"),
            }
        }
        assert!(matches!(
            normalise_weights(&[0.0, 0.0]),
            Err(RayError::AllZeroWeights { count: 2 })
        ));
        assert!(matches!(normalise_weights(&[]), Err(RayError::NoWeights)));
    }
}
