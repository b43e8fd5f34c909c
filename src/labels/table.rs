//! Label tables (`--label-table`): names and colours by label value.
//!
//! - FreeSurferColorLUT and 3D Slicer `.ctbl`/`.txt`: lines `index name R G B A`
//!   (`#` comments, blank lines and CRLF allowed; A is ignored).
//! - NiiVue label JSON: arrays `R`, `G`, `B` (0 … 255), optional `I` (the values;
//!   0 … n−1 if absent) and `labels` (names).
//! - MRIcron `.lut`: 768 bytes, 256 reds then 256 greens then 256 blues, with names
//!   from `NAME.txt` beside `NAME.lut` (`index name` lines) when that file exists.

use crate::volume::{VolumeError, short_name};
use std::collections::BTreeMap;
use std::path::Path;

/// A label's name and colour from a table; either may be missing.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TableEntry {
    pub name: Option<String>,
    pub color: Option<[u8; 3]>,
}

/// Names and colours by label value.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LabelTable {
    pub entries: BTreeMap<u16, TableEntry>,
}

/// Reads a label table, telling the kind by extension and content.
pub fn read_table(path: &Path) -> Result<LabelTable, VolumeError> {
    let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
    let lower = path.to_string_lossy().to_ascii_lowercase();
    if lower.ends_with(".lut") && bytes.len() == 768 {
        let mut t = mricron_lut(&bytes);
        let names = path.with_extension("txt");
        if names.is_file() {
            let text = std::fs::read(&names).map_err(|e| VolumeError::io(&names, e))?;
            for (value, name) in index_names(&String::from_utf8_lossy(&text), &names)? {
                t.entries.entry(value).or_default().name = Some(name);
            }
        }
        return Ok(t);
    }
    let text = String::from_utf8_lossy(&bytes);
    if lower.ends_with(".json") || text.trim_start().starts_with('{') {
        return niivue_json(&text, path);
    }
    if lower.ends_with(".lut") {
        return Err(VolumeError::invalid(
            path,
            format!(
                "an MRIcron .lut must be 768 bytes (256 reds, greens, blues); this one is {}",
                bytes.len()
            ),
        ));
    }
    lut_text(&text, path)
}

/// `index name R G B A` lines (FreeSurfer, Slicer). Names may hold spaces.
pub fn lut_text(text: &str, path: &Path) -> Result<LabelTable, VolumeError> {
    let mut t = LabelTable::default();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = || VolumeError::AtLine {
            path: path.to_owned(),
            line: i + 1,
            message: format!(
                "expected 'index name R G B A', found '{}'",
                short_name(line).trim_matches('"')
            ),
        };
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let channel = |s: &str| s.parse::<u8>().ok();
        let (value, name, rgb) = match tokens.as_slice() {
            [value, name @ .., r, g, b, a] if !name.is_empty() && a.parse::<f64>().is_ok() => {
                (value, name, [*r, *g, *b])
            }
            [value, name, r, g, b] => (value, std::slice::from_ref(name), [*r, *g, *b]),
            _ => return Err(bad()),
        };
        let value = value.parse::<u16>().map_err(|_| bad())?;
        let [r, g, b] = rgb.map(channel);
        let (Some(r), Some(g), Some(b)) = (r, g, b) else {
            return Err(bad());
        };
        t.entries.insert(
            value,
            TableEntry {
                name: Some(name.join(" ")),
                color: Some([r, g, b]),
            },
        );
    }
    if t.entries.is_empty() {
        return Err(VolumeError::invalid(
            path,
            "no 'index name R G B A' lines: not a label table",
        ));
    }
    Ok(t)
}

/// `index name` lines (MRIcron's names beside a `.lut`).
fn index_names(text: &str, path: &Path) -> Result<Vec<(u16, String)>, VolumeError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let parsed = line
            .split_once(char::is_whitespace)
            .and_then(|(v, n)| Some((v.parse::<u16>().ok()?, n.trim().to_owned())));
        match parsed {
            Some((v, n)) if !n.is_empty() => out.push((v, n)),
            _ => {
                return Err(VolumeError::AtLine {
                    path: path.to_owned(),
                    line: i + 1,
                    message: format!(
                        "expected 'index name', found '{}'",
                        short_name(line).trim_matches('"')
                    ),
                });
            }
        }
    }
    Ok(out)
}

/// MRIcron's 768-byte colour table: 256 reds, then greens, then blues.
fn mricron_lut(bytes: &[u8]) -> LabelTable {
    let entries = (0..256)
        .map(|i| {
            let color = [bytes[i], bytes[256 + i], bytes[512 + i]];
            (
                i as u16,
                TableEntry {
                    name: None,
                    color: Some(color),
                },
            )
        })
        .collect();
    LabelTable { entries }
}

/// NiiVue's label colour map JSON.
pub fn niivue_json(text: &str, path: &Path) -> Result<LabelTable, VolumeError> {
    let bad = |m: String| VolumeError::invalid(path, format!("NiiVue label JSON: {m}"));
    let j: serde_json::Value =
        serde_json::from_str(text).map_err(|e| bad(format!("not valid JSON ({e})")))?;
    let array = |key: &str| -> Result<Option<Vec<f64>>, VolumeError> {
        match j.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_array()
                .and_then(|a| a.iter().map(serde_json::Value::as_f64).collect())
                .map(Some)
                .ok_or_else(|| bad(format!("\"{key}\" is not an array of numbers"))),
        }
    };
    let (Some(r), Some(g), Some(b)) = (array("R")?, array("G")?, array("B")?) else {
        return Err(bad("needs arrays \"R\", \"G\" and \"B\"".into()));
    };
    let n = r.len();
    if g.len() != n || b.len() != n {
        return Err(bad(format!(
            "\"R\", \"G\", \"B\" hold {}, {}, {} numbers; they must be equally long",
            n,
            g.len(),
            b.len()
        )));
    }
    let values: Vec<u16> = match array("I")? {
        Some(i) if i.len() != n => {
            return Err(bad(format!(
                "\"I\" holds {} values for {n} colours",
                i.len()
            )));
        }
        Some(i) => i
            .iter()
            .map(|&v| (v.fract() == 0.0 && (0.0..=65535.0).contains(&v)).then_some(v as u16))
            .collect::<Option<_>>()
            .ok_or_else(
                || bad("\"I\" holds a value that is not a whole number 0 … 65535".into()),
            )?,
        None => (0..n as u16).collect(),
    };
    let names: Option<Vec<String>> = match j.get("labels") {
        None => None,
        Some(v) => Some(
            v.as_array()
                .and_then(|a| a.iter().map(|s| s.as_str().map(str::to_owned)).collect())
                .ok_or_else(|| bad("\"labels\" is not an array of strings".into()))?,
        ),
    };
    let channel = |x: f64| -> Result<u8, VolumeError> {
        (0.0..=255.0)
            .contains(&x)
            .then_some(x.round() as u8)
            .ok_or_else(|| bad(format!("colour value {x} is outside 0 … 255")))
    };
    let mut t = LabelTable::default();
    for k in 0..n {
        t.entries.insert(
            values[k],
            TableEntry {
                name: names.as_ref().and_then(|l| l.get(k).cloned()),
                color: Some([channel(r[k])?, channel(g[k])?, channel(b[k])?]),
            },
        );
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lut_text_reads_crlf_comments_and_spaces_in_names() {
        let text = "#No. Label Name: R G B A\r\n\r\n0  Unknown 0 0 0 0\r\n14175  wm_rh_S_temporal 221 60 60 0\r\n7 left lung 10 20 30 255\r\n";
        let t = lut_text(text, Path::new("t.txt")).expect("parses");
        assert_eq!(t.entries.len(), 3);
        let e = &t.entries[&14175];
        assert_eq!(e.name.as_deref(), Some("wm_rh_S_temporal"));
        assert_eq!(e.color, Some([221, 60, 60]));
        assert_eq!(t.entries[&7].name.as_deref(), Some("left lung"));
    }

    #[test]
    fn malformed_line_names_file_and_line() {
        let text = "# c\n1 a 1 2 3 0\n2 b 300 2 3 0\n";
        let e = lut_text(text, Path::new("t.txt")).expect_err("300 is no colour");
        assert_eq!(
            e.to_string(),
            "t.txt:3: expected 'index name R G B A', found '2 b 300 2 3 0'"
        );
        let e = lut_text("1 2 3\n", Path::new("t.txt")).expect_err("short");
        assert!(e.to_string().starts_with("t.txt:1: expected"), "{e}");
    }

    #[test]
    fn niivue_json_with_and_without_values_and_names() {
        let t = niivue_json(
            r#"{"R":[0,255],"G":[0,1],"B":[0,2],"A":[0,255],"I":[0,9],"labels":["bg","x"]}"#,
            Path::new("a.json"),
        )
        .expect("parses");
        assert_eq!(t.entries[&9].name.as_deref(), Some("x"));
        assert_eq!(t.entries[&9].color, Some([255, 1, 2]));
        let t =
            niivue_json(r#"{"R":[0,5],"G":[0,6],"B":[0,7]}"#, Path::new("b.json")).expect("parses");
        assert_eq!(t.entries[&1].color, Some([5, 6, 7]));
        assert_eq!(t.entries[&1].name, None);
        let e = niivue_json(r#"{"R":[0],"G":[0,6],"B":[0,7]}"#, Path::new("c.json"))
            .expect_err("uneven");
        assert!(e.to_string().contains("equally long"), "{e}");
    }

    #[test]
    fn mricron_lut_with_names_beside_it() {
        let dir = tempfile::tempdir().expect("temp dir");
        let lut = dir.path().join("atlas.nii.lut");
        let mut bytes = vec![0u8; 768];
        bytes[3] = 200; // red of 3
        bytes[256 + 3] = 100;
        bytes[512 + 3] = 50;
        std::fs::write(&lut, &bytes).expect("write");
        std::fs::write(dir.path().join("atlas.nii.txt"), "3 area three\n").expect("write");
        let t = read_table(&lut).expect("reads");
        assert_eq!(t.entries.len(), 256);
        assert_eq!(t.entries[&3].color, Some([200, 100, 50]));
        assert_eq!(t.entries[&3].name.as_deref(), Some("area three"));
        assert_eq!(t.entries[&4].name, None);
    }
}
