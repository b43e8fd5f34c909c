//! What `--annotate` draws on a figure: orientation letters on a slice's edges and a
//! scale bar, in a small built-in bitmap font (no font files, the same pixels everywhere).

/// The 5×7 font: each glyph's character, then its seven rows as two hex digits each
/// (five bits, the most significant on the left).
const FONT: &str = "A0E11111F111111 I0E04040404040E L1010101010101F P1E11111E101010 \
                    R1E11111E141211 S0F10100E01011E c00000E1010110E m00001A15151111 \
                    00E11131519110E 1040C040404040E 20E11010204081F 51F101E0101110E";

/// A glyph's seven rows (` ` is blank), or `None` for a character the font lacks.
fn glyph(c: char) -> Option<[u8; 7]> {
    if c == ' ' {
        return Some([0; 7]);
    }
    let rows = FONT
        .split_whitespace()
        .find_map(|g| g.strip_prefix(c))
        .filter(|rows| rows.len() == 14)?;
    let mut out = [0u8; 7];
    for (i, o) in out.iter_mut().enumerate() {
        *o = u8::from_str_radix(&rows[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

/// Pixel size of one font dot for an image `width` wide.
fn dot(width: usize) -> usize {
    (width / 200).clamp(1, 4)
}

/// Draws `text` with its top-left corner at (x, y) in RGB pixels `rgb` (`width` wide),
/// white with a dark outline; dots outside the image are dropped.
pub fn draw_text(rgb: &mut [u8], width: usize, x: isize, y: isize, text: &str) {
    let d = dot(width) as isize;
    let height = (rgb.len() / 3 / width.max(1)) as isize;
    let mut put = |px: isize, py: isize, v: u8| {
        if px >= 0 && py >= 0 && px < width as isize && py < height {
            let i = 3 * (py as usize * width + px as usize);
            rgb[i..i + 3].fill(v);
        }
    };
    let dots: Vec<(isize, isize)> = text
        .chars()
        .enumerate()
        .filter_map(|(n, c)| glyph(c).map(|g| (n as isize * 6 * d, g)))
        .flat_map(|(gx, g)| {
            (0..7isize).flat_map(move |row| {
                (0..5isize)
                    .filter(move |col| g[row as usize] >> (4 - col) & 1 != 0)
                    .map(move |col| (gx + col * d, row * d))
            })
        })
        .collect();
    // The outline first, then the glyphs over it.
    for pass in [0u8, 255] {
        let grow = if pass == 0 { 1 } else { 0 };
        for &(gx, gy) in &dots {
            for yy in -grow..d + grow {
                for xx in -grow..d + grow {
                    put(x + gx + xx, y + gy + yy, pass);
                }
            }
        }
    }
}

/// Size in pixels of `text` drawn for an image `width` wide.
fn text_size(width: usize, text: &str) -> [isize; 2] {
    let d = dot(width) as isize;
    [text.chars().count() as isize * 6 * d - d, 7 * d]
}

/// A scale bar for a figure `width` units wide whose units are `mm_per_unit` apart: the
/// longest 1-2-5 length (mm) that fits in a fifth of the width, and its label ("2 cm").
pub fn scale_bar_length(mm_per_unit: f64, width: f64) -> Option<(f64, String)> {
    if mm_per_unit.is_nan() || mm_per_unit <= 0.0 {
        return None;
    }
    let mm = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0]
        .into_iter()
        .rev()
        .find(|&mm| mm / mm_per_unit <= width / 5.0)?;
    let label = if mm >= 10.0 {
        format!("{} cm", mm / 10.0)
    } else {
        format!("{mm} mm")
    };
    Some((mm, label))
}

/// Orientation letters at the middle of each edge (left, right, top, bottom) and a scale
/// bar in the bottom-right corner of RGB pixels `rgb` (`width` wide), whose pixels are
/// `pixel_mm` apart.
pub fn annotate(rgb: &mut [u8], width: usize, letters: [char; 4], pixel_mm: f64) {
    let height = rgb.len() / 3 / width.max(1);
    let (w, h) = (width as isize, height as isize);
    let m = 2 * dot(width) as isize;
    let [lw, lh] = text_size(width, "A");
    let [left, right, top, bottom] = letters.map(|c| c.to_string());
    draw_text(rgb, width, m, (h - lh) / 2, &left);
    draw_text(rgb, width, w - lw - m, (h - lh) / 2, &right);
    draw_text(rgb, width, (w - lw) / 2, m, &top);
    draw_text(rgb, width, (w - lw) / 2, h - lh - m, &bottom);

    if width < 40 {
        return;
    }
    let Some((mm, label)) = scale_bar_length(pixel_mm, w as f64) else {
        return;
    };
    let bar = (mm / pixel_mm).round() as isize;
    let [tw, th] = text_size(width, &label);
    let x1 = w - m - lw - 2 * m;
    let y = h - m - th - 2 * m;
    draw_text(rgb, width, x1 - tw, y - th - m, &label);
    for yy in y - 1..y + dot(width) as isize + 1 {
        for xx in x1 - bar - 1..=x1 {
            if xx >= 0 && yy >= 0 && xx < w && yy < h {
                let edge = yy == y - 1 || yy == y + dot(width) as isize || xx == x1 - bar - 1;
                let i = 3 * (yy as usize * width + xx as usize);
                rgb[i..i + 3].fill(if edge { 0 } else { 255 });
            }
        }
    }
}

/// The orientation marker of a 3-D figure: the R, A and S axes as `camera` sees them,
/// labelled, in the bottom-left corner of RGB pixels `rgb` (`width` wide).
pub fn orientation_marker(rgb: &mut [u8], width: usize, camera: &crate::render::Camera) {
    let height = rgb.len() / 3 / width.max(1);
    let d = dot(width) as f32;
    let len = (width as f32 * 0.05).max(16.0);
    let origin = (6.0 * d + len, height as f32 - 6.0 * d - len);
    let (right, up) = camera.screen_axes();
    let back = camera.backward();
    let mut axes = [
        (glam::Vec3::X, 'R', [230u8, 90, 80]),
        (glam::Vec3::Y, 'A', [110, 210, 100]),
        (glam::Vec3::Z, 'S', [100, 150, 255]),
    ];
    // Far axes first, so near ones draw over them.
    axes.sort_by(|a, b| a.0.dot(back).total_cmp(&b.0.dot(back)));
    for (axis, letter, color) in axes {
        let (dx, dy) = (axis.dot(right) * len, -axis.dot(up) * len);
        let steps = (dx.abs().max(dy.abs()) as usize).max(1);
        for k in 0..=steps {
            let t = k as f32 / steps as f32;
            let (x, y) = (origin.0 + dx * t, origin.1 + dy * t);
            for oy in 0..d as usize + 1 {
                for ox in 0..d as usize + 1 {
                    let (px, py) = (x as usize + ox, y as usize + oy);
                    if px < width && py < height {
                        let i = 3 * (py * width + px);
                        rgb[i..i + 3].copy_from_slice(&color);
                    }
                }
            }
        }
        let [tw, th] = text_size(width, "A");
        draw_text(
            rgb,
            width,
            (origin.0 + dx * 1.45) as isize - tw / 2,
            (origin.1 + dy * 1.45) as isize - th / 2,
            &letter.to_string(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_and_bar_change_pixels_only_where_drawn() {
        let (w, h) = (128usize, 96usize);
        let mut rgb = vec![100u8; w * h * 3];
        annotate(&mut rgb, w, ['R', 'L', 'A', 'P'], 1.0);
        let white = rgb.chunks(3).filter(|p| p[0] == 255).count();
        assert!(white > 40, "letters and bar drawn: {white}");
        // The centre is left alone.
        let c = 3 * (h / 2 * w + w / 2);
        assert_eq!(rgb[c], 100);
        // A 20 mm bar at 1 mm/pixel fits a fifth of 128 px: "2 cm".
        assert_eq!(glyph('2'), Some([0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F]));
        assert_eq!(glyph('A'), Some([0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11]));
        assert!(glyph('c').is_some() && glyph('Q').is_none());
    }
}
