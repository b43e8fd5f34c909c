//! Transfer functions: data value → colour and opacity, in the data's own units.
//!
//! A [`TransferFunction`] holds two piecewise-linear lists over the physical value
//! (Hounsfield units for CT, scanner units for MR): opacity points and colour stops.
//! [`Preset`]s give the starting points a radiologist expects; the CT presets are in
//! absolute HU, the MR and the CAO paper's single-colour preset are placed relative to
//! the volume's value range and resolved to data units when they are built.
//!
//! For the GPU a function is baked into a [`Lut`] of [`LUT_ENTRIES`] straight-RGBA
//! entries over the volume's value range; [`Lut::sample`] is the CPU twin of the
//! shader's filtered fetch and [`Lut::is_transparent_over`] the empty-space test.
//! Opacities are per unit step (one voxel); [`correct_opacity`] rescales them to the
//! ray caster's step.

mod error;
mod function;
mod lut;
mod presets;

pub use error::TfError;
pub use function::{ColorStop, OpacityPoint, TransferFunction};
pub use lut::{LUT_ENTRIES, Lut, correct_opacity};
pub use presets::Preset;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Stats;

    fn stats(min: f64, max: f64) -> Stats {
        Stats {
            min,
            max,
            mean: (min + max) / 2.0,
            non_finite: 0,
            finite: 1000,
        }
    }

    fn ct() -> Stats {
        stats(-1024.0, 3071.0)
    }

    fn mr() -> Stats {
        stats(0.0, 812.0)
    }

    /// SplitMix64: a deterministic source of test values without a rand dependency.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        /// Uniform in [lo, hi).
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn simple() -> TransferFunction {
        TransferFunction {
            name: "test".into(),
            opacity: OpacityPoint::list(&[(0.0, 0.0), (100.0, 1.0), (200.0, 0.5)]),
            color: ColorStop::list(&[(0.0, [0.0; 3]), (200.0, [1.0, 0.5, 0.0])]),
        }
    }

    fn close(a: [f32; 4], b: [f32; 4], tol: f32) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn eval_hits_points_interpolates_and_clamps() {
        let tf = simple();
        tf.validate().expect("simple TF is valid");
        assert_eq!(tf.eval(0.0), [0.0, 0.0, 0.0, 0.0]);
        assert_eq!(tf.eval(100.0)[3], 1.0);
        assert_eq!(tf.eval(200.0), [1.0, 0.5, 0.0, 0.5]);
        assert!(close(tf.eval(50.0), [0.25, 0.125, 0.0, 0.5], 1e-6));
        assert!(close(tf.eval(150.0), [0.75, 0.375, 0.0, 0.75], 1e-6));
        assert!(close(tf.eval(100.0), [0.5, 0.25, 0.0, 1.0], 1e-6));
        // Linear: the midpoint of any two points inside one segment is their mean.
        for (a, b) in [(10.0, 90.0), (120.0, 190.0)] {
            let (ea, eb, em) = (tf.eval(a), tf.eval(b), tf.eval((a + b) / 2.0));
            let mean: [f32; 4] = std::array::from_fn(|c| (ea[c] + eb[c]) / 2.0);
            assert!(close(em, mean, 1e-6), "{em:?} vs {mean:?}");
        }
        assert_eq!(tf.eval(-1e6), tf.eval(0.0));
        assert_eq!(tf.eval(f64::NEG_INFINITY), tf.eval(0.0));
        assert_eq!(tf.eval(1e6), tf.eval(200.0));
        assert_eq!(tf.eval(f64::NAN), [0.0; 4]);
    }

    #[test]
    fn steps_are_right_continuous() {
        let mut tf = simple();
        tf.opacity = OpacityPoint::list(&[(100.0, 0.0), (100.0, 0.7)]);
        tf.validate().expect("ties are allowed");
        assert_eq!(tf.eval(99.999)[3], 0.0);
        assert_eq!(tf.eval(100.0)[3], 0.7);
        assert_eq!(tf.eval(100.001)[3], 0.7);
        assert_eq!(tf.visible_range(), Some((100.0, f64::INFINITY)));
    }

    #[test]
    fn presets_hit_their_control_points_exactly() {
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &ct());
            for o in &tf.opacity {
                assert_eq!(tf.eval(o.value)[3], o.alpha, "{p} opacity at {}", o.value);
            }
            for c in &tf.color {
                assert_eq!(tf.eval(c.value)[..3], c.rgb, "{p} colour at {}", c.value);
            }
        }
    }

    #[test]
    fn bake_matches_eval_and_sample_interpolates() {
        const { assert!(LUT_ENTRIES >= 1024) };
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &ct());
            // −1024…3071 in 4096 entries: one HU per entry, every position exact.
            let lut = tf.bake(-1024.0, 3071.0, LUT_ENTRIES);
            assert_eq!(lut.rgba.len(), LUT_ENTRIES);
            for (i, e) in lut.rgba.iter().enumerate() {
                let v = lut.entry_value(i);
                assert_eq!(v, -1024.0 + i as f64);
                assert_eq!(*e, tf.eval(v), "{p} entry {i}");
                assert_eq!(lut.sample(v), *e, "{p} sample at entry {i}");
            }
            // Between entries: the lerp of the two neighbours.
            for i in [0, 100, 1174, 1500, 4094] {
                let (a, b) = (lut.rgba[i], lut.rgba[i + 1]);
                let s = lut.sample(lut.entry_value(i) + 0.25);
                let want: [f32; 4] = std::array::from_fn(|c| a[c] * 0.75 + b[c] * 0.25);
                assert!(close(s, want, 1e-6), "{p} between {i} and {}", i + 1);
            }
            // Clamp to the edge entries outside the range.
            assert_eq!(lut.sample(-5000.0), lut.rgba[0]);
            assert_eq!(lut.sample(1e9), lut.rgba[LUT_ENTRIES - 1]);
        }
    }

    #[test]
    fn bake_over_an_unaligned_range_matches_eval() {
        let tf = TransferFunction::preset(Preset::MrT1Brain, &mr());
        let lut = tf.bake(-3.7, 812.0, LUT_ENTRIES);
        assert_eq!(lut.entry_value(0), -3.7);
        assert!((lut.entry_value(LUT_ENTRIES - 1) - 812.0).abs() < 1e-12);
        for (i, e) in lut.rgba.iter().enumerate() {
            let v = lut.entry_value(i);
            assert_eq!(*e, tf.eval(v));
            // t is not exactly i here; the lerp weight is off by ~1e-13.
            assert!(close(lut.sample(v), *e, 1e-6), "entry {i}");
        }
        // A linear TF segment is reproduced between entries up to f32 rounding.
        let mut rng = Rng(7);
        for _ in 0..1000 {
            let v = rng.range(0.26 * 812.0, 0.44 * 812.0);
            assert!(close(lut.sample(v), tf.eval(v), 1e-5), "at {v}");
        }
    }

    #[test]
    fn bake_makes_degenerate_ranges_usable() {
        let tf = simple();
        let lut = tf.bake(50.0, 50.0, 0);
        assert_eq!(lut.rgba.len(), 2);
        assert!(lut.min < 50.0 && lut.max > 50.0);
        let lut = tf.bake(200.0, 0.0, 16);
        assert_eq!((lut.min, lut.max), (0.0, 200.0));
        let lut = tf.bake(f64::NAN, 1.0, 16);
        assert_eq!((lut.min, lut.max), (0.0, 1.0));
    }

    #[test]
    fn correct_opacity_is_the_step_power_law() {
        for i in 0..=1000 {
            let a = i as f32 / 1000.0;
            assert_eq!(correct_opacity(a, 1.0), a, "step 1 is identity at {a}");
            let half = correct_opacity(a, 0.5);
            let two = 1.0 - (1.0 - f64::from(half)).powi(2);
            assert!((two - f64::from(a)).abs() < 1e-6, "two half steps at {a}");
            let double = correct_opacity(a, 2.0);
            assert!((double - correct_opacity(half, 4.0)).abs() < 1e-6);
        }
        for step in [0.01, 0.5, 1.0, 1.7, 100.0] {
            assert_eq!(correct_opacity(0.0, step), 0.0);
            assert_eq!(correct_opacity(1.0, step), 1.0);
        }
        assert_eq!(correct_opacity(1e-9, 1.0), 1e-9);
        assert_eq!(correct_opacity(0.5, 0.0), 0.0);
        assert_eq!(correct_opacity(f32::NAN, 1.0), 0.0);
        assert_eq!(correct_opacity(0.3, f32::INFINITY), 1.0);
    }

    #[test]
    fn is_transparent_over_is_conservative() {
        let mut rng = Rng(42);
        // Presets over CT and unaligned ranges: the claim holds for the table and the
        // function (their opacity features are much wider than one entry).
        let ranges = [(-1024.0, 3071.0), (-2048.0, 3071.0), (-1000.3, 2000.7)];
        let mut said_transparent = 0;
        for p in Preset::ALL {
            for &(min, max) in &ranges {
                let tf = TransferFunction::preset(p, &stats(min, max));
                let lut = tf.bake(min, max, LUT_ENTRIES);
                for _ in 0..300 {
                    let a = rng.range(min, max);
                    let b = (a + rng.range(0.0, 400.0)).min(max);
                    if !lut.is_transparent_over(b, a) {
                        continue;
                    }
                    said_transparent += 1;
                    for k in 0..=200 {
                        let v = a + (b - a) * k as f64 / 200.0;
                        assert_eq!(lut.sample(v)[3], 0.0, "{p} sample at {v} in [{a}, {b}]");
                        assert_eq!(tf.eval(v)[3], 0.0, "{p} eval at {v} in [{a}, {b}]");
                    }
                }
            }
        }
        assert!(said_transparent > 100, "test must exercise the true case");

        // Random functions: the claim always holds for what the table renders.
        for _ in 0..200 {
            let mut v = rng.range(-100.0, 100.0);
            let opacity = (0..6)
                .map(|_| {
                    v += rng.range(0.0, 30.0);
                    let alpha = if rng.next().is_multiple_of(2) {
                        0.0
                    } else {
                        rng.range(0.0, 1.0) as f32
                    };
                    OpacityPoint { value: v, alpha }
                })
                .collect();
            let tf = TransferFunction {
                name: "random".into(),
                opacity,
                color: vec![ColorStop {
                    value: 0.0,
                    rgb: [1.0; 3],
                }],
            };
            tf.validate().expect("random TF is valid");
            let lut = tf.bake(-120.0, 300.0, 1024);
            for _ in 0..50 {
                let a = rng.range(-200.0, 350.0);
                let b = a + rng.range(0.0, 20.0);
                if lut.is_transparent_over(a, b) {
                    for k in 0..=100 {
                        let v = a + (b - a) * k as f64 / 100.0;
                        assert_eq!(lut.sample(v)[3], 0.0, "sample at {v} in [{a}, {b}]");
                    }
                }
            }
        }

        // One entry per unit; opacity 0 up to 100, rising after. The test reaches two
        // entries past floor(t(hi)): 98.5 → entries ..=100 (all 0), 99 → entry 101.
        let mut tf = simple();
        tf.opacity = OpacityPoint::list(&[(100.0, 0.0), (150.0, 1.0)]);
        let lut = tf.bake(0.0, 200.0, 201);
        assert!(lut.is_transparent_over(-10.0, 50.0));
        assert!(lut.is_transparent_over(98.5, 10.0));
        assert!(!lut.is_transparent_over(10.0, 99.0));
        assert!(!lut.is_transparent_over(120.0, 130.0));
        assert!(!lut.is_transparent_over(f64::NAN, 1.0));
    }

    #[test]
    fn window_level_round_trips() {
        for p in Preset::ALL {
            let tf = TransferFunction::preset(p, &ct());
            let (w, l) = tf.window_level();
            let moved = tf.with_window_level(400.0, 40.0);
            moved.validate().expect("remapped preset stays valid");
            let (w2, l2) = moved.window_level();
            assert!((w2 - 400.0).abs() < 1e-9 && (l2 - 40.0).abs() < 1e-9);
            // The shape moves with the points.
            let map = |v: f64| 40.0 - 200.0 + (v - (l - w / 2.0)) / w * 400.0;
            // map() rounds differently from the remap, so allow an ulp-sized lerp weight.
            for o in &tf.opacity {
                assert!((moved.eval(map(o.value))[3] - o.alpha).abs() < 1e-6);
            }
            let back = moved.with_window_level(w, l);
            for (a, b) in tf.opacity.iter().zip(&back.opacity) {
                assert!((a.value - b.value).abs() < 1e-9 && a.alpha == b.alpha);
            }
            for (a, b) in tf.color.iter().zip(&back.color) {
                assert!((a.value - b.value).abs() < 1e-9 && a.rgb == b.rgb);
            }
        }
        let bone = TransferFunction::preset(Preset::CtBone, &ct());
        assert_eq!(bone.window_level(), (1350.0, 825.0));
        assert_eq!(bone.with_window_level(f64::NAN, 0.0), bone);
        let step = bone.with_window_level(-5.0, 300.0);
        step.validate().expect("a collapsed TF is a valid step");
        assert_eq!(step.window_level(), (0.0, 300.0));
    }

    #[test]
    fn presets_validate_and_names_round_trip() {
        for p in Preset::ALL {
            assert_eq!(Preset::from_name(p.name()).expect("own name"), p);
            assert_eq!(p.name().parse::<Preset>().expect("FromStr"), p);
            let json = serde_json::to_string(&p).expect("serialize preset");
            assert_eq!(json, format!("\"{}\"", p.name()));
            let back: Preset = serde_json::from_str(&json).expect("deserialize preset");
            assert_eq!(back, p);
            for s in [ct(), mr(), stats(5.0, 5.0), stats(-1e6, 1e6)] {
                let tf = TransferFunction::preset(p, &s);
                assert_eq!(tf.name, p.name());
                tf.validate()
                    .unwrap_or_else(|e| panic!("{p} over {s:?} is invalid: {e}"));
                assert!(tf.visible_range().is_some());
            }
        }
        assert_eq!(
            Preset::from_name(" CT-Bone ").expect("case"),
            Preset::CtBone
        );
        let err = Preset::from_name("bone").expect_err("not a preset");
        let msg = err.to_string();
        assert!(msg.contains("\"bone\""), "{msg}");
        for p in Preset::ALL {
            assert!(msg.contains(p.name()), "{msg}");
        }
    }

    #[test]
    fn presets_are_what_a_radiologist_expects() {
        let at = |p, v| TransferFunction::preset(p, &ct()).eval(v);
        // Bone: air, fat, muscle invisible; bone opaque and light.
        for v in [-1000.0, -100.0, 40.0, 150.0] {
            assert_eq!(at(Preset::CtBone, v)[3], 0.0, "bone at {v}");
        }
        let b = at(Preset::CtBone, 1000.0);
        assert!(b[3] > 0.8 && b[0] > 0.9 && b[1] > 0.85 && b[2] > 0.75);
        // Soft tissue: muscle semi-transparent red.
        let m = at(Preset::CtSoftTissue, 50.0);
        assert!(m[3] > 0.05 && m[3] < 0.3 && m[0] > 2.0 * m[1]);
        // Vessels: contrast red, bone white, unenhanced tissue hidden.
        assert_eq!(at(Preset::CtVessels, 50.0)[3], 0.0);
        let c = at(Preset::CtVessels, 300.0);
        assert!(c[3] > 0.4 && c[0] > 3.0 * c[1]);
        let w = at(Preset::CtVessels, 900.0);
        assert!(w.iter().all(|&x| x > 0.85));
        // Relative presets follow the volume's range.
        let tf = TransferFunction::preset(Preset::MrT1Brain, &mr());
        let (lo, hi) = tf.visible_range().expect("visible");
        assert!((lo - 0.10 * 812.0).abs() < 1e-9 && hi == f64::INFINITY);
        assert!(tf.opacity.iter().all(|o| (0.0..=812.0).contains(&o.value)));
        // CAO: one colour everywhere, opacity a non-decreasing ramp to 1.
        let cao = TransferFunction::preset(Preset::CaoSingleColor, &mr());
        let mut last = 0.0;
        for k in 0..=100 {
            let e = cao.eval(812.0 * k as f64 / 100.0);
            assert_eq!(e[..3], [0.9, 0.9, 0.9]);
            assert!(e[3] >= last);
            last = e[3];
        }
        assert_eq!(last, 1.0);
    }

    #[test]
    fn default_preset_follows_the_range() {
        assert_eq!(Preset::default_for(&ct()), Preset::CtBone);
        assert_eq!(Preset::default_for(&mr()), Preset::MrT1Brain);
        assert_eq!(Preset::default_for(&stats(0.0, 255.0)), Preset::MrT1Brain);
    }

    #[test]
    fn visible_range_brackets_the_visible_part() {
        let tf = simple();
        assert_eq!(tf.visible_range(), Some((0.0, f64::INFINITY)));
        let mut peak = simple();
        peak.opacity.push(OpacityPoint {
            value: 300.0,
            alpha: 0.0,
        });
        assert_eq!(peak.visible_range(), Some((0.0, 300.0)));
        peak.opacity.iter_mut().for_each(|o| o.alpha = 0.0);
        assert_eq!(peak.visible_range(), None);
    }

    #[test]
    fn serde_round_trips_a_tf() {
        let tf = TransferFunction::preset(Preset::CtSoftTissue, &ct());
        let json = serde_json::to_string_pretty(&tf).expect("serialize");
        assert!(json.contains("\"alpha\"") && json.contains("\"rgb\""));
        let back: TransferFunction = serde_json::from_str(&json).expect("deserialize");
        assert_eq!(back, tf);
    }

    #[test]
    fn invalid_tfs_are_rejected_with_clear_messages() {
        let check = |tf: TransferFunction, needles: &[&str]| {
            let msg = tf.validate().expect_err("must be invalid").to_string();
            for n in needles {
                assert!(msg.contains(n), "{msg:?} lacks {n:?}");
            }
        };
        let mut tf = simple();
        tf.opacity.clear();
        check(tf, &["\"test\"", "opacity list is empty"]);
        let mut tf = simple();
        tf.color.clear();
        check(tf, &["colour list is empty"]);
        let mut tf = simple();
        tf.opacity[1].value = f64::NAN;
        check(tf, &["opacity point 1", "NaN", "not a finite"]);
        let mut tf = simple();
        tf.opacity[2].value = 50.0;
        check(
            tf,
            &["opacity point 2 at 50", "after a point at 100", "sort"],
        );
        let mut tf = simple();
        tf.opacity[1].alpha = 1.5;
        check(tf, &["opacity point 1", "alpha 1.5", "[0, 1]"]);
        let mut tf = simple();
        tf.color[1].rgb = [255.0, 128.0, 0.0];
        check(tf, &["colour stop 1", "not 0–255"]);
        let mut tf = simple();
        tf.color[0].rgb[2] = f32::NAN;
        check(tf, &["colour stop 0"]);
    }
}
