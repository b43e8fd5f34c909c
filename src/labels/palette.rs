//! Colours for ids that no file or table colours.

/// A distinct, never-black colour for label `id`, the same every time: hues step by the
/// golden ratio of a turn, so neighbouring ids land far apart on the colour wheel, and
/// saturation and brightness alternate over three levels so equal hues still differ.
pub fn palette_color(id: u16) -> [u8; 3] {
    const GOLDEN: f64 = 0.618_033_988_749_895;
    let h = (id as f64 * GOLDEN).fract();
    let (s, v) = [(0.75, 0.95), (0.55, 0.85), (0.9, 0.75)][id as usize % 3];
    hsv_to_rgb(h, s, v)
}

/// HSV (each 0 … 1) to 8-bit RGB.
fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [u8; 3] {
    let h6 = h * 6.0;
    let sector = h6.floor() as i32 % 6;
    let f = h6 - h6.floor();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match sector {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r, g, b].map(|c| (c * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_is_bright_and_neighbours_differ() {
        for id in 0..=1000u16 {
            let c = palette_color(id);
            assert!(c.iter().any(|&x| x >= 150), "id {id}: {c:?} is dark");
            let d = palette_color(id + 1);
            let dist: i32 = c
                .iter()
                .zip(d)
                .map(|(a, b)| (*a as i32 - b as i32).abs())
                .sum();
            assert!(dist > 60, "ids {id} and {}: {c:?} vs {d:?}", id + 1);
        }
        assert_eq!(palette_color(7), palette_color(7));
    }
}
