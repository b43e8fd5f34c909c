//! Why a transfer function or a preset name is refused.

/// Everything that can make a transfer function or a preset name unusable.
#[derive(Debug, thiserror::Error)]
pub enum TfError {
    #[error("transfer function \"{tf}\": the {list} list is empty; give at least one point")]
    Empty { tf: String, list: &'static str },
    #[error(
        "transfer function \"{tf}\": {list} point {index} has value {value}, not a finite number"
    )]
    NonFinite {
        tf: String,
        list: &'static str,
        index: usize,
        value: f64,
    },
    #[error(
        "transfer function \"{tf}\": {list} point {index} at {value} comes after a point at {previous}; sort the points by value (equal values make a step)"
    )]
    Unsorted {
        tf: String,
        list: &'static str,
        index: usize,
        value: f64,
        previous: f64,
    },
    #[error("transfer function \"{tf}\": opacity point {index} has alpha {alpha}, outside [0, 1]")]
    AlphaOutOfRange {
        tf: String,
        index: usize,
        alpha: f32,
    },
    #[error(
        "transfer function \"{tf}\": colour stop {index} has rgb {rgb:?}, outside [0, 1] (colours are linear RGB in [0, 1], not 0–255)"
    )]
    RgbOutOfRange {
        tf: String,
        index: usize,
        rgb: [f32; 3],
    },
    #[error("unknown transfer-function preset \"{name}\"; valid presets are {valid}")]
    UnknownPreset { name: String, valid: String },
}
