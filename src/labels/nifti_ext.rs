//! Label names and colours from a NIfTI header extension: the CaretExtension XML
//! (code 0 or 30) that TotalSegmentator and Connectome Workbench write, whose
//! `<LabelTable>` holds `<Label Key="5" Red="0" Green="1" Blue="1" Alpha="1">liver</Label>`
//! with colours as 0 … 1 floats.
//!
//! The volume loader skips extensions, so they are read here: after the fixed header
//! come 4 bytes whose first is non-zero when extensions follow, then blocks of
//! `esize` (i32, including its 8-byte head), `ecode` (i32) and `esize − 8` bytes of data,
//! up to `vox_offset`.

use super::raw::{FileNames, SegmentKey};
use super::table::TableEntry;
use crate::volume::nifti;
use std::io::Read;
use std::path::Path;

/// Most extension bytes read; label tables are kilobytes.
const MAX_EXTENSIONS: u64 = 64 << 20;

/// The label names in `path`'s NIfTI extensions; none when it is no NIfTI file or has
/// none. A label table that cannot be read is a warning, never an error: the voxels
/// are still usable.
pub fn read_names(path: &Path, warnings: &mut Vec<String>) -> FileNames {
    let mut names = FileNames::default();
    let Some(blocks) = extension_blocks(path) else {
        return names;
    };
    for (code, data) in blocks {
        let text = String::from_utf8_lossy(&data);
        if !text.contains("<LabelTable") {
            continue;
        }
        let labels = caret_labels(&text);
        if labels.is_empty() {
            warnings.push(format!(
                "NIfTI extension (code {code}) holds a LabelTable but no <Label Key=…> could be read; labels are unnamed"
            ));
        }
        for (value, entry) in labels {
            names.entries.insert(SegmentKey { layer: 0, value }, entry);
        }
    }
    names
}

/// (ecode, data) of each extension block, or `None` when the file is no NIfTI.
pub fn extension_blocks(path: &Path) -> Option<Vec<(i32, Vec<u8>)>> {
    let header_path = nifti::resolve_paths(path).header;
    let (mut r, _, _) = nifti::open_maybe_gz(&header_path).ok()?;
    let h = nifti::read_header(&mut r, &header_path).ok()?;
    let mut extender = [0u8; 4];
    if r.read_exact(&mut extender).is_err() || extender[0] == 0 {
        return Some(Vec::new());
    }
    let int = |b: [u8; 4]| {
        if h.little_endian {
            i32::from_le_bytes(b)
        } else {
            i32::from_be_bytes(b)
        }
    };
    // Single files: blocks end at vox_offset; a .hdr holds blocks up to its end.
    let end = if h.single_file {
        (h.vox_offset as u64).min(h.size() + 4 + MAX_EXTENSIONS)
    } else {
        h.size() + 4 + MAX_EXTENSIONS
    };
    let mut at = h.size() + 4;
    let mut blocks = Vec::new();
    while at + 8 <= end {
        let mut head = [0u8; 8];
        if r.read_exact(&mut head).is_err() {
            break;
        }
        let esize = int([head[0], head[1], head[2], head[3]]);
        let ecode = int([head[4], head[5], head[6], head[7]]);
        if esize < 8 || at + esize as u64 > end {
            break;
        }
        let mut data = vec![0u8; esize as usize - 8];
        if r.read_exact(&mut data).is_err() {
            break;
        }
        blocks.push((ecode, data));
        at += esize as u64;
    }
    Some(blocks)
}

/// The `<Label …>` elements of a CaretExtension `<LabelTable>`.
pub fn caret_labels(xml: &str) -> Vec<(u16, TableEntry)> {
    let mut out = Vec::new();
    let mut rest = xml;
    while let Some(start) = rest.find("<Label") {
        let after = &rest[start + "<Label".len()..];
        // `<LabelTable>` starts the same way: only `<Label` followed by space or `>`.
        if !after.starts_with([' ', '\t', '\n', '\r', '>', '/']) {
            rest = after;
            continue;
        }
        let Some(tag_end) = after.find('>') else {
            break;
        };
        let attrs = &after[..tag_end];
        let self_closing = attrs.ends_with('/');
        let body_start = &after[tag_end + 1..];
        let (content, next) = if self_closing {
            ("", body_start)
        } else {
            match body_start.find("</Label>") {
                Some(e) => (&body_start[..e], &body_start[e + "</Label>".len()..]),
                None => break,
            }
        };
        rest = next;
        let attr = |name: &str| attribute(attrs, name);
        let Some(key) = attr("Key").and_then(|k| k.trim().parse::<u16>().ok()) else {
            continue;
        };
        let channel = |name: &str| {
            attr(name)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| (0.0..=1.0).contains(v))
                .map(|v| (v * 255.0).round() as u8)
        };
        let color = match (channel("Red"), channel("Green"), channel("Blue")) {
            (Some(r), Some(g), Some(b)) => Some([r, g, b]),
            _ => None,
        };
        let name = text_content(content);
        out.push((
            key,
            TableEntry {
                name: (!name.is_empty()).then_some(name),
                color,
            },
        ));
    }
    out
}

/// The value of attribute `name` in a tag's attribute text, entities decoded.
fn attribute(attrs: &str, name: &str) -> Option<String> {
    let mut rest = attrs;
    loop {
        let i = rest.find(name)?;
        let before_ok = i == 0 || rest[..i].ends_with(char::is_whitespace);
        let after = rest[i + name.len()..].trim_start();
        if before_ok && let Some(v) = after.strip_prefix('=') {
            let v = v.trim_start();
            let quote = v.chars().next().filter(|c| *c == '"' || *c == '\'')?;
            let v = &v[1..];
            let end = v.find(quote)?;
            return Some(unescape(&v[..end]));
        }
        rest = &rest[i + name.len()..];
    }
}

/// Element text: CDATA sections kept verbatim, other text entity-decoded, trimmed.
fn text_content(s: &str) -> String {
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find("<![CDATA[") {
        out.push_str(&unescape(&rest[..i]));
        let after = &rest[i + "<![CDATA[".len()..];
        let end = after.find("]]>").unwrap_or(after.len());
        out.push_str(&after[..end]);
        rest = after.get(end + 3..).unwrap_or("");
    }
    out.push_str(&unescape(rest));
    out.trim().to_owned()
}

/// XML's five named entities and numeric character references.
fn unescape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('&') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        let Some(end) = after.find(';').filter(|&e| e <= 10) else {
            out.push('&');
            rest = after;
            continue;
        };
        let entity = &after[..end];
        let c = match entity {
            "amp" => Some('&'),
            "lt" => Some('<'),
            "gt" => Some('>'),
            "quot" => Some('"'),
            "apos" => Some('\''),
            e => e
                .strip_prefix("#x")
                .and_then(|h| u32::from_str_radix(h, 16).ok())
                .or_else(|| e.strip_prefix('#').and_then(|d| d.parse().ok()))
                .and_then(char::from_u32),
        };
        match c {
            Some(c) => {
                out.push(c);
                rest = &after[end + 1..];
            }
            None => {
                out.push('&');
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caret_label_table_with_cdata_and_entities() {
        let xml = r#"<?xml version="1.0"?><CaretExtension><LabelTable>
<Label Key="5" Red="0.0" Green="1.0" Blue="1.0" Alpha="1"><![CDATA[liver]]></Label>
<Label Key="6" Red="1.0" Green="0.5019607843137255" Blue="0.0" Alpha="1">a &amp; b</Label>
<Label Key="7" Red="2" Green="0" Blue="0"/>
<Label Key="x">bad key</Label>
</LabelTable></CaretExtension>"#;
        let labels = caret_labels(xml);
        assert_eq!(labels.len(), 3);
        assert_eq!(labels[0].0, 5);
        assert_eq!(labels[0].1.name.as_deref(), Some("liver"));
        assert_eq!(labels[0].1.color, Some([0, 255, 255]));
        assert_eq!(labels[1].1.name.as_deref(), Some("a & b"));
        assert_eq!(labels[1].1.color, Some([255, 128, 0]));
        // Red outside 0 … 1: no colour, no name.
        assert_eq!(labels[2].1, TableEntry::default());
    }

    #[test]
    fn attributes_need_a_word_boundary() {
        assert_eq!(
            attribute(r#" MyKey="1" Key="2""#, "Key").as_deref(),
            Some("2")
        );
        assert_eq!(attribute(r#" Key = '3'"#, "Key").as_deref(), Some("3"));
        assert_eq!(attribute(r#" Red="1""#, "Key"), None);
    }
}
