//! The transfer function itself: piecewise-linear opacity and colour lists over the
//! data's units, evaluated, validated, windowed and baked into a [`Lut`].

use super::error::TfError;
use super::lut::{Lut, entry_value};

/// One opacity control point: data value (physical units) → opacity in [0, 1].
///
/// The opacity is per unit step (one voxel); see [`correct_opacity`](super::correct_opacity).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OpacityPoint {
    pub value: f64,
    pub alpha: f32,
}

/// One colour stop: data value → linear RGB in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ColorStop {
    pub value: f64,
    pub rgb: [f32; 3],
}

impl OpacityPoint {
    /// Points from (value, alpha) pairs.
    pub fn list(points: &[(f64, f32)]) -> Vec<OpacityPoint> {
        points
            .iter()
            .map(|&(value, alpha)| OpacityPoint { value, alpha })
            .collect()
    }
}

impl ColorStop {
    /// Stops from (value, rgb) pairs.
    pub fn list(stops: &[(f64, [f32; 3])]) -> Vec<ColorStop> {
        stops
            .iter()
            .map(|&(value, rgb)| ColorStop { value, rgb })
            .collect()
    }
}

/// A 1-D transfer function: piecewise-linear opacity and colour over the data's units.
///
/// Both lists are sorted by value; two points with the same value make a step (the
/// function takes the later point's value from there on). Outside a list's range the
/// end points hold. A function read from a file must pass [`TransferFunction::validate`]
/// before use.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TransferFunction {
    pub name: String,
    pub opacity: Vec<OpacityPoint>,
    pub color: Vec<ColorStop>,
}

/// A usable, non-empty range from `[min, max]`: swapped if reversed, widened around the
/// value if empty (a constant volume), `[0, 1]` if not finite.
pub(super) fn usable_range(min: f64, max: f64) -> (f64, f64) {
    if !(min.is_finite() && max.is_finite()) {
        return (0.0, 1.0);
    }
    let (lo, hi) = (min.min(max), min.max(max));
    if hi > lo {
        (lo, hi)
    } else {
        let d = 0.5f64.max(lo.abs() * 1e-9);
        (lo - d, lo + d)
    }
}

/// Linear interpolation in f64, exact at `t == 0`.
fn lerp(a: f32, b: f32, t: f64) -> f32 {
    (f64::from(a) + (f64::from(b) - f64::from(a)) * t) as f32
}

/// The segment of a sorted list around `value`: (index of left point, index of right
/// point, t in [0, 1)). Right-continuous at steps; clamps outside; `None` if empty.
fn segment(values: impl Fn(usize) -> f64, len: usize, value: f64) -> Option<(usize, usize, f64)> {
    if len == 0 {
        return None;
    }
    // First point strictly right of `value` (binary search; the list is sorted).
    let (mut lo, mut hi) = (0, len);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if values(mid) <= value {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    Some(match lo {
        0 => (0, 0, 0.0),
        i if i == len => (len - 1, len - 1, 0.0),
        i => {
            let (a, b) = (values(i - 1), values(i));
            (i - 1, i, (value - a) / (b - a))
        }
    })
}

impl TransferFunction {
    /// Checks that both lists are non-empty, finite and sorted by value (ties allowed
    /// for steps), alphas are in [0, 1] and colours in [0, 1].
    pub fn validate(&self) -> Result<(), TfError> {
        check_values(&self.name, "opacity", self.opacity.iter().map(|p| p.value))?;
        check_values(&self.name, "colour", self.color.iter().map(|c| c.value))?;
        if let Some((index, p)) = self
            .opacity
            .iter()
            .enumerate()
            .find(|(_, p)| !(0.0..=1.0).contains(&p.alpha))
        {
            return Err(TfError::AlphaOutOfRange {
                tf: self.name.clone(),
                index,
                alpha: p.alpha,
            });
        }
        if let Some((index, c)) = self
            .color
            .iter()
            .enumerate()
            .find(|(_, c)| !c.rgb.iter().all(|x| (0.0..=1.0).contains(x)))
        {
            return Err(TfError::RgbOutOfRange {
                tf: self.name.clone(),
                index,
                rgb: c.rgb,
            });
        }
        Ok(())
    }

    /// Piecewise-linear evaluation, clamped to the end points outside their range.
    /// Returns straight RGBA. At a step (equal values) the later point wins. NaN (an
    /// empty voxel) and empty lists give 0.
    pub fn eval(&self, value: f64) -> [f32; 4] {
        if value.is_nan() {
            return [0.0; 4];
        }
        let alpha = segment(|i| self.opacity[i].value, self.opacity.len(), value)
            .map_or(0.0, |(i, j, t)| {
                lerp(self.opacity[i].alpha, self.opacity[j].alpha, t)
            });
        let rgb = segment(|i| self.color[i].value, self.color.len(), value).map_or(
            [0.0; 3],
            |(i, j, t)| {
                let (a, b) = (self.color[i].rgb, self.color[j].rgb);
                std::array::from_fn(|c| lerp(a[c], b[c], t))
            },
        );
        [rgb[0], rgb[1], rgb[2], alpha]
    }

    /// The smallest closed value range outside which opacity is 0, or `None` if the
    /// function is fully transparent. An end is infinite when the first/last opacity
    /// point is visible (evaluation clamps). Used for empty-space skipping and for
    /// choosing the LUT range (intersect it with the volume's range).
    pub fn visible_range(&self) -> Option<(f64, f64)> {
        let pts = &self.opacity;
        let first = pts.iter().position(|p| p.alpha > 0.0)?;
        let last = pts.iter().rposition(|p| p.alpha > 0.0)?;
        let lo = if first == 0 {
            f64::NEG_INFINITY
        } else {
            pts[first - 1].value
        };
        let hi = if last + 1 == pts.len() {
            f64::INFINITY
        } else {
            pts[last + 1].value
        };
        Some((lo, hi))
    }

    /// Bakes `entries` samples over `[min, max]` (the caller passes the volume's value
    /// range): entry `i` is [`TransferFunction::eval`] at [`Lut::entry_value`]`(i)`.
    /// At least 2 entries are made; an empty or non-finite range is made usable as
    /// for relative presets (widened around a constant value, `[0, 1]` if not finite).
    pub fn bake(&self, min: f64, max: f64, entries: usize) -> Lut {
        let (min, max) = usable_range(min, max);
        let len = entries.max(2);
        let window = match self.span() {
            Some((lo, hi)) if hi > lo => [lo, hi],
            Some((v, _)) => [v - 0.5, v + 0.5],
            None => [min, max],
        };
        Lut {
            min,
            max,
            rgba: (0..len)
                .map(|i| self.eval(entry_value(min, max, len, i)))
                .collect(),
            window,
            iso: self
                .half_opacity_value()
                .unwrap_or((window[0] + window[1]) / 2.0),
        }
    }

    /// The first value at which the opacity reaches half its maximum (linear between
    /// points), or `None` for a fully transparent function.
    pub fn half_opacity_value(&self) -> Option<f64> {
        let peak = self.opacity.iter().map(|p| p.alpha).fold(0.0f32, f32::max);
        if peak <= 0.0 {
            return None;
        }
        let half = peak / 2.0;
        let first = self.opacity.iter().position(|p| p.alpha >= half)?;
        if first == 0 {
            return Some(self.opacity[0].value);
        }
        let (a, b) = (self.opacity[first - 1], self.opacity[first]);
        let f = ((half - a.alpha) / (b.alpha - a.alpha)) as f64;
        Some(a.value + (b.value - a.value) * f)
    }

    /// Window/level: a copy whose points are linearly remapped so the span of its points
    /// (first to last value over both lists) becomes `[level − window/2, level + window/2]`.
    ///
    /// `window` must be > 0; a window ≤ 0 is taken as 0, which collapses the function
    /// into a step at `level`. A function whose points all share one value is moved to
    /// `level`. A non-finite window or level, or a function without points, returns an
    /// unchanged copy.
    pub fn with_window_level(&self, window: f64, level: f64) -> TransferFunction {
        let Some((lo, hi)) = self.span() else {
            return self.clone();
        };
        if !(window.is_finite() && level.is_finite()) {
            return self.clone();
        }
        let window = window.max(0.0);
        let start = level - window / 2.0;
        let span = hi - lo;
        let remap = |v: f64| {
            if span > 0.0 {
                start + (v - lo) / span * window
            } else {
                level
            }
        };
        TransferFunction {
            name: self.name.clone(),
            opacity: self
                .opacity
                .iter()
                .map(|p| OpacityPoint {
                    value: remap(p.value),
                    ..*p
                })
                .collect(),
            color: self
                .color
                .iter()
                .map(|c| ColorStop {
                    value: remap(c.value),
                    ..*c
                })
                .collect(),
        }
    }

    /// The current (window, level) of the point span: (last − first, (first + last) / 2)
    /// over both lists; (0, 0) for a function without points.
    pub fn window_level(&self) -> (f64, f64) {
        match self.span() {
            Some((lo, hi)) => (hi - lo, lo + (hi - lo) / 2.0),
            None => (0.0, 0.0),
        }
    }

    /// Smallest and largest point value over both lists (NaN ignored).
    fn span(&self) -> Option<(f64, f64)> {
        let values = self
            .opacity
            .iter()
            .map(|p| p.value)
            .chain(self.color.iter().map(|c| c.value))
            .filter(|v| !v.is_nan());
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        (lo <= hi).then_some((lo, hi))
    }
}

/// Non-empty, finite, sorted (ties allowed).
fn check_values(
    tf: &str,
    list: &'static str,
    values: impl Iterator<Item = f64>,
) -> Result<(), TfError> {
    let mut previous: Option<f64> = None;
    for (index, value) in values.enumerate() {
        if !value.is_finite() {
            return Err(TfError::NonFinite {
                tf: tf.to_owned(),
                list,
                index,
                value,
            });
        }
        if let Some(previous) = previous
            && value < previous
        {
            return Err(TfError::Unsorted {
                tf: tf.to_owned(),
                list,
                index,
                value,
                previous,
            });
        }
        previous = Some(value);
    }
    match previous {
        Some(_) => Ok(()),
        None => Err(TfError::Empty {
            tf: tf.to_owned(),
            list,
        }),
    }
}
