//! How a segmentation shows and which segments each clip shape cuts — what the user
//! chooses (`--segment`, a scene's `segmentation`, the viewer's Segments panel) — turned
//! into the classes and looks every stage reads ([`crate::texels::segments`]).

use super::{LabelMap, SegmentKey};
use crate::clip::{ClipShape, Cuts};
use crate::texels::segments::{ClassLook, SegmentTexels};
use std::collections::{BTreeSet, HashMap};

/// How one segment (or the voxels in none) shows.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentStyle {
    pub visible: bool,
    /// Multiplies the transfer function's opacity, in [0, 1].
    pub opacity: f32,
    /// `None`: the segment's own colour (its file's, the table's or the palette's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub color: Option<[u8; 3]>,
    /// The colour replaces the transfer function's; otherwise it tints (multiplies) it.
    pub replace: bool,
    /// Only the segment's boundary shows.
    pub outline: bool,
}

impl Default for SegmentStyle {
    fn default() -> Self {
        SegmentStyle {
            visible: true,
            opacity: 1.0,
            color: None,
            replace: false,
            outline: false,
        }
    }
}

/// One segment's style as scene files list it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Styled {
    #[serde(default)]
    pub layer: u16,
    pub value: u16,
    #[serde(flatten)]
    pub style: SegmentStyle,
}

/// The styles of a segmentation: the voxels in no segment, and each segment that differs
/// from `segments_default`.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Styles {
    /// Voxels in no segment (shown through the transfer function alone by default).
    pub unlabelled: SegmentStyle,
    /// Every segment not listed in `segments`.
    pub segments_default: SegmentStyle,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub segments: Vec<Styled>,
}

impl Styles {
    /// The style of `key`.
    pub fn get(&self, key: SegmentKey) -> SegmentStyle {
        self.segments
            .iter()
            .find(|s| (s.layer, s.value) == (key.layer, key.value))
            .map_or(self.segments_default, |s| s.style)
    }

    /// Sets the style of `key`.
    pub fn set(&mut self, key: SegmentKey, style: SegmentStyle) {
        let found = self
            .segments
            .iter_mut()
            .find(|s| (s.layer, s.value) == (key.layer, key.value));
        match found {
            Some(s) => s.style = style,
            None => {
                self.segments.push(Styled {
                    layer: key.layer,
                    value: key.value,
                    style,
                });
                self.segments.sort_by_key(|s| (s.layer, s.value));
            }
        }
    }

    /// Applies `spec` (`PATTERN:CHANGE,…`, see [`parse_changes`]) to every segment it
    /// names (`PATTERN` as [`LabelMap::find`]; `unlabelled` for the voxels in none).
    pub fn apply(&mut self, labels: &LabelMap, spec: &str) -> Result<(), String> {
        let (pattern, changes) = spec
            .rsplit_once(':')
            .ok_or_else(|| format!("--segment {spec:?}: expected PATTERN:CHANGE[,CHANGE…]"))?;
        let changes = parse_changes(changes).map_err(|e| format!("--segment {spec:?}: {e}"))?;
        let change = |s: &mut SegmentStyle| changes.iter().for_each(|c| c.apply(s));
        if pattern.eq_ignore_ascii_case("unlabelled") {
            change(&mut self.unlabelled);
            return Ok(());
        }
        if pattern.trim() == "*" {
            // Every segment: the default, and those styled apart.
            change(&mut self.segments_default);
            self.segments.iter_mut().for_each(|s| change(&mut s.style));
            return Ok(());
        }
        let keys = labels.find(pattern);
        if keys.is_empty() {
            return Err(format!(
                "--segment {spec:?}: no segment of {} is named or numbered {pattern:?}",
                labels.display_path()
            ));
        }
        for key in keys {
            let mut style = self.get(key);
            change(&mut style);
            self.set(key, style);
        }
        Ok(())
    }
}

/// One change `--segment` makes to a style.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    Hide,
    Show,
    Tint,
    Replace,
    Outline,
    Fill,
    Opacity(f32),
    Color([u8; 3]),
}

impl Change {
    pub fn apply(self, s: &mut SegmentStyle) {
        match self {
            Change::Hide => s.visible = false,
            Change::Show => s.visible = true,
            Change::Tint => s.replace = false,
            Change::Replace => s.replace = true,
            Change::Outline => s.outline = true,
            Change::Fill => s.outline = false,
            Change::Opacity(o) => s.opacity = o,
            Change::Color(c) => s.color = Some(c),
        }
    }
}

/// One `--segment` change list: `hide`, `show`, `opacity=F`, `color=#rrggbb`, `tint`,
/// `replace`, `outline`, `fill`, comma-separated.
pub fn parse_changes(changes: &str) -> Result<Vec<Change>, String> {
    changes
        .split(',')
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .map(|c| {
            let (key, value) = c.split_once('=').unwrap_or((c, ""));
            Ok(match key {
                "hide" => Change::Hide,
                "show" => Change::Show,
                "tint" => Change::Tint,
                "replace" => Change::Replace,
                "outline" => Change::Outline,
                "fill" => Change::Fill,
                "opacity" => Change::Opacity(
                    value
                        .parse()
                        .ok()
                        .filter(|o: &f32| (0.0..=1.0).contains(o))
                        .ok_or_else(|| format!("opacity {value:?} is not a number in 0…1"))?,
                ),
                "color" | "colour" => Change::Color(
                    parse_hex(value).ok_or_else(|| format!("colour {value:?} is not #rrggbb"))?,
                ),
                _ => {
                    return Err(format!(
                        "unknown change {c:?} (hide, show, opacity=F, color=#rrggbb, tint, replace, outline, fill)"
                    ));
                }
            })
        })
        .collect()
}

fn parse_hex(s: &str) -> Option<[u8; 3]> {
    let h = s.strip_prefix('#').unwrap_or(s);
    if h.len() != 6 {
        return None;
    }
    let v = u32::from_str_radix(h, 16).ok()?;
    Some([(v >> 16) as u8, (v >> 8) as u8, v as u8])
}

/// The classes of a label map: one per combination of its layers' values found in it.
#[derive(Debug, Clone)]
pub struct Classes {
    /// The class of each voxel (x fastest).
    pub of_voxel: Vec<u16>,
    /// Each class's segments (none: voxels in no segment).
    pub members: Vec<Vec<SegmentKey>>,
}

impl Classes {
    /// The classes of `labels`; an error if it has more combinations than 65 536.
    pub fn of(labels: &LabelMap) -> Result<Classes, String> {
        let n = labels.dims.iter().product::<usize>();
        let mut ids: HashMap<Vec<u16>, u16> = HashMap::new();
        let mut members = Vec::new();
        let mut of_voxel = Vec::with_capacity(n);
        // Class 0 is always "in no segment", so unlabelled voxels keep a fixed class.
        ids.insert(vec![0; labels.layers.len()], 0);
        members.push(Vec::new());
        if let [layer] = &labels.layers[..] {
            return Self::of_layer(labels, layer);
        }
        let mut combo = vec![0u16; labels.layers.len()];
        for i in 0..n {
            for (c, layer) in combo.iter_mut().zip(&labels.layers) {
                *c = layer[i];
            }
            let id = match ids.get(&combo) {
                Some(&id) => id,
                None => {
                    let id = u16::try_from(members.len()).map_err(|_| {
                        format!(
                            "{}: more than 65 536 combinations of overlapping segments",
                            labels.display_path()
                        )
                    })?;
                    let keys = (0u16..)
                        .zip(&combo)
                        .filter(|&(_, &v)| v != 0)
                        .map(|(layer, &value)| SegmentKey { layer, value })
                        .collect();
                    members.push(keys);
                    ids.insert(combo.clone(), id);
                    id
                }
            };
            of_voxel.push(id);
        }
        Ok(Classes { of_voxel, members })
    }
}

impl Classes {
    /// One layer: a class per value present (class 0: value 0), by a table of values.
    fn of_layer(labels: &LabelMap, layer: &[u16]) -> Result<Classes, String> {
        let mut class_of = vec![u16::MAX; 1 << 16];
        class_of[0] = 0;
        let mut members = vec![Vec::new()];
        for &v in layer {
            if class_of[v as usize] == u16::MAX {
                class_of[v as usize] = u16::try_from(members.len()).map_err(|_| {
                    format!("{}: more than 65 535 label values", labels.display_path())
                })?;
                members.push(vec![SegmentKey { layer: 0, value: v }]);
            }
        }
        let of_voxel = layer.iter().map(|&v| class_of[v as usize]).collect();
        Ok(Classes { of_voxel, members })
    }
}

/// Which segments a shape's [`Cuts`] names, resolved against a label map.
struct Cut {
    keys: BTreeSet<SegmentKey>,
    unlabelled: bool,
    except: bool,
}

impl Cut {
    fn new(cuts: &Cuts, labels: &LabelMap) -> Cut {
        let (names, except) = match cuts {
            Cuts::All => (&[][..], true),
            Cuts::Only(n) => (&n[..], false),
            Cuts::Except(n) => (&n[..], true),
        };
        let unlabelled = names
            .iter()
            .any(|n| n.eq_ignore_ascii_case("unlabelled") || n.trim() == "0");
        let keys = names.iter().flat_map(|n| labels.find(n)).collect();
        Cut {
            keys,
            unlabelled,
            except,
        }
    }

    /// Whether the shape cuts a voxel of `members` (all of them; none: unlabelled).
    fn cuts(&self, members: &[SegmentKey]) -> bool {
        let named = if members.is_empty() {
            self.unlabelled
        } else {
            members.iter().all(|k| self.keys.contains(k))
        };
        named != self.except
    }
}

/// The look of every class: its top visible segment's colour and mode (the highest
/// layer), the largest opacity among its visible segments, and the shapes that cut it.
pub fn looks(
    labels: &LabelMap,
    classes: &Classes,
    styles: &Styles,
    shapes: &[ClipShape],
) -> Vec<ClassLook> {
    let cuts: Vec<Cut> = shapes.iter().map(|s| Cut::new(&s.cuts, labels)).collect();
    let own_color = |key: SegmentKey| {
        labels
            .index_of(key)
            .map_or([255; 3], |i| labels.segments[i].color)
    };
    let mut looks: Vec<ClassLook> = classes
        .members
        .iter()
        .map(|members| {
            let carved_by = (0..)
                .zip(&cuts)
                .filter(|(_, c)| c.cuts(members))
                .fold(0u32, |bits, (s, _)| bits | 1 << s);
            let shown = |s: &SegmentStyle| s.visible && s.opacity > 0.0;
            let visible: Vec<(SegmentKey, SegmentStyle)> = members
                .iter()
                .map(|&k| (k, styles.get(k)))
                .filter(|(_, s)| shown(s))
                .collect();
            let (style, color) = match visible.last() {
                Some(&(key, style)) => (style, style.color.unwrap_or_else(|| own_color(key))),
                None if members.is_empty() => {
                    let s = styles.unlabelled;
                    (s, s.color.unwrap_or([255; 3]))
                }
                None => (
                    SegmentStyle {
                        visible: false,
                        ..Default::default()
                    },
                    [0; 3],
                ),
            };
            let opacity = if members.is_empty() {
                if shown(&style) { style.opacity } else { 0.0 }
            } else {
                visible.iter().map(|(_, s)| s.opacity).fold(0.0, f32::max)
            };
            ClassLook {
                color,
                opacity,
                replace: style.replace,
                outline: style.outline,
                carved_by,
            }
        })
        .collect();
    // A hidden class's colour never shows: it takes the mode of the shown ones where they
    // agree, so that the shaders need not look the mode up per sample (`SEGMENT_MODES`).
    let shown = |c: &&ClassLook| c.opacity > 0.0;
    if let Some(first) = looks.iter().find(shown).map(|c| c.replace)
        && looks.iter().filter(shown).all(|c| c.replace == first)
    {
        looks.iter_mut().for_each(|c| c.replace = first);
    }
    looks
}

/// Checks that every segment a clip shape names is in `labels`: one line per problem.
pub fn check_cuts(labels: &LabelMap, shapes: &[ClipShape]) -> Result<(), String> {
    for (i, shape) in shapes.iter().enumerate() {
        let names = match &shape.cuts {
            Cuts::All => continue,
            Cuts::Only(n) | Cuts::Except(n) => n,
        };
        for name in names {
            let background = name.eq_ignore_ascii_case("unlabelled") || name.trim() == "0";
            if !background && labels.find(name).is_empty() {
                return Err(format!(
                    "clip shape {}: no segment of {} is named or numbered {name:?}",
                    i + 1,
                    labels.display_path()
                ));
            }
        }
    }
    Ok(())
}

/// A segmentation ready for the GPU: its classes with `styles`' looks and `shapes`' cuts.
pub fn segment_texels(
    labels: &LabelMap,
    classes: &Classes,
    styles: &Styles,
    shapes: &[ClipShape],
) -> SegmentTexels {
    SegmentTexels::new(
        labels.dims,
        classes.of_voxel.clone(),
        looks(labels, classes, styles, shapes),
    )
}
