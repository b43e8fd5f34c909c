//! Segmentations in the viewer: the label map the document shows with the volume, its
//! styles, and the Segments panel that edits them (search, visibility, opacity, colour,
//! tint/replace, outline; "only", show/hide all). What the styles and the clip shapes'
//! cuts make of it on the GPU is kept in step by `sync.rs`.

use crate::clip::ClipShape;
use crate::labels::style::{self, Classes, SegmentStyle, Styles};
use crate::labels::{self, LabelMap, SegmentKey};
use crate::scene::SegmentationSource;
use crate::texels::segments::SegmentTexels;
use crate::volume::{Volume, display_path};
use std::path::PathBuf;
use std::sync::Arc;

/// A segmentation placed on the document's volume, with how its segments show.
#[derive(Debug, Clone)]
pub struct Segmentation {
    /// The label file and the colour table it was read with (as a scene names them).
    pub path: PathBuf,
    pub table: Option<PathBuf>,
    pub styles: Styles,
    /// The map on the volume's grid (RAS, as uploaded) and its classes; shared, never
    /// edited.
    pub labels: Arc<LabelMap>,
    pub classes: Arc<Classes>,
}

impl Segmentation {
    /// Reads `source` onto `volume`'s grid; the notes are warnings for the user (partial
    /// overlap, clip shapes naming segments the map lacks).
    pub fn load(
        source: SegmentationSource,
        volume: &Volume,
        shapes: &[ClipShape],
    ) -> Result<(Segmentation, Vec<String>), String> {
        let what = display_path(&source.path);
        let loaded = labels::load(&source.path, source.table.as_deref(), volume)
            .map_err(|e| format!("segmentation: {e}"))?;
        let mut notes: Vec<String> = loaded
            .warnings
            .iter()
            .map(|w| format!("{what}: {w}"))
            .collect();
        let labels = loaded.labels;
        let classes = Classes::of(&labels)?;
        if let Err(e) = style::check_cuts(&labels, shapes) {
            notes.push(format!("{e} (it cuts nothing by that name)"));
        }
        Ok((
            Segmentation {
                path: source.path,
                table: source.table,
                styles: source.styles,
                labels: Arc::new(labels),
                classes: Arc::new(classes),
            },
            notes,
        ))
    }

    /// What a scene file keeps of it.
    pub fn source(&self) -> SegmentationSource {
        SegmentationSource {
            path: self.path.clone(),
            table: self.table.clone(),
            styles: self.styles.clone(),
        }
    }

    /// Its classes with the looks the styles and `shapes`' cuts give them.
    pub fn texels(&self, shapes: &[ClipShape]) -> SegmentTexels {
        style::segment_texels(&self.labels, &self.classes, &self.styles, shapes)
    }

    /// The names of a class's segments, for the hover line ("(unlabelled)" for none).
    pub fn names(&self, members: &[SegmentKey]) -> String {
        if members.is_empty() {
            return UNLABELLED.to_owned();
        }
        members
            .iter()
            .map(|&k| match self.labels.index_of(k) {
                Some(i) => format!("{} ({})", self.labels.segments[i].name, k.value),
                None => format!("label {}", k.value),
            })
            .collect::<Vec<_>>()
            .join(" + ")
    }
}

/// The row of the voxels in no segment.
pub const UNLABELLED: &str = "(unlabelled)";

/// One row of the Segments panel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Row {
    Unlabelled,
    /// An index into [`LabelMap::segments`].
    Segment(usize),
}

/// The rows whose name contains `query` (case-insensitive; empty: all): the unlabelled
/// voxels, then the segments present on the grid (named but absent ones are left out).
pub fn filter_rows(labels: &LabelMap, query: &str) -> Vec<Row> {
    let q = query.trim().to_lowercase();
    let hit = |name: &str| q.is_empty() || name.to_lowercase().contains(&q);
    let unlabelled = hit(UNLABELLED) || hit("unlabelled");
    unlabelled
        .then_some(Row::Unlabelled)
        .into_iter()
        .chain(
            labels
                .segments
                .iter()
                .enumerate()
                .filter(|(_, s)| s.voxels > 0 && hit(&s.name))
                .map(|(i, _)| Row::Segment(i)),
        )
        .collect()
}

/// The Segments panel's own state.
#[derive(Debug, Default)]
pub struct SegmentsPanel {
    pub search: String,
}

/// Height of one row of the list, in points.
const ROW_HEIGHT: f32 = 22.0;

impl SegmentsPanel {
    /// The panel: search, show/hide all, and a row per segment listed.
    pub fn show(&mut self, ui: &mut egui::Ui, seg: &mut Segmentation) {
        let labels = Arc::clone(&seg.labels);
        let present = labels.segments.iter().filter(|s| s.voxels > 0).count();
        ui.weak(format!(
            "{}: {present} segments",
            seg.path.file_name().map_or_else(
                || seg.path.display().to_string(),
                |n| n.to_string_lossy().into_owned()
            )
        ));
        ui.horizontal(|ui| {
            ui.label("Search");
            ui.add(
                egui::TextEdit::singleline(&mut self.search)
                    .hint_text("name")
                    .desired_width(140.0),
            )
            .accessible_name("Search segments");
        });
        let rows = filter_rows(&labels, &self.search);
        ui.horizontal(|ui| {
            let tip = "Every segment listed (the search narrows the list)";
            if ui.button("Show all").on_hover_text(tip).clicked() {
                set_visible(&mut seg.styles, &labels, &rows, true);
            }
            if ui.button("Hide all").on_hover_text(tip).clicked() {
                set_visible(&mut seg.styles, &labels, &rows, false);
            }
            ui.weak(format!("{} listed", rows.len()));
        });
        egui::ScrollArea::vertical()
            .id_salt("segments")
            .min_scrolled_height(ROW_HEIGHT * 10.0)
            .max_height(ROW_HEIGHT * 12.0)
            .auto_shrink([false, true])
            .show_rows(ui, ROW_HEIGHT, rows.len(), |ui, range| {
                for &row in &rows[range] {
                    row_ui(ui, seg, &labels, row);
                }
            });
    }
}

/// Shows or hides every row of `rows`.
fn set_visible(styles: &mut Styles, labels: &LabelMap, rows: &[Row], visible: bool) {
    for &row in rows {
        match row {
            Row::Unlabelled => styles.unlabelled.visible = visible,
            Row::Segment(i) => {
                let key = labels.segments[i].key;
                let mut s = styles.get(key);
                s.visible = visible;
                styles.set(key, s);
            }
        }
    }
}

/// Shows `row` alone: every other segment and the unlabelled voxels hidden.
fn only(styles: &mut Styles, labels: &LabelMap, row: Row) {
    let all: Vec<Row> = std::iter::once(Row::Unlabelled)
        .chain((0..labels.segments.len()).map(Row::Segment))
        .collect();
    set_visible(styles, labels, &all, false);
    set_visible(styles, labels, &[row], true);
}

/// One row: colour, opacity, only, tint/replace, outline, and visibility with the name
/// and value.
fn row_ui(ui: &mut egui::Ui, seg: &mut Segmentation, labels: &LabelMap, row: Row) {
    let (name, value, own) = match row {
        Row::Unlabelled => (UNLABELLED.to_owned(), None, [255; 3]),
        Row::Segment(i) => {
            let s = &labels.segments[i];
            (s.name.clone(), Some(s.key), s.color)
        }
    };
    let before: SegmentStyle = match value {
        Some(k) => seg.styles.get(k),
        None => seg.styles.unlabelled,
    };
    let mut st = before;
    let mut only_this = false;
    ui.horizontal(|ui| {
        ui.set_height(ROW_HEIGHT - ui.spacing().item_spacing.y);
        let mut rgb = st.color.unwrap_or(own);
        if egui::color_picker::color_edit_button_srgb(ui, &mut rgb)
            .on_hover_text("Colour (tints the transfer function's, or replaces it)")
            .changed()
        {
            st.color = Some(rgb);
        }
        ui.spacing_mut().slider_width = 46.0;
        ui.add(egui::Slider::new(&mut st.opacity, 0.0..=1.0).show_value(false))
            .on_hover_text(format!("Opacity {:.2}", st.opacity));
        only_this = ui
            .small_button("only")
            .on_hover_text("Show this one alone")
            .clicked();
        let mode = if st.replace { "R" } else { "T" };
        if ui
            .selectable_label(st.replace, mode)
            .on_hover_text("T: the colour tints the transfer function's · R: replaces it")
            .clicked()
        {
            st.replace = !st.replace;
        }
        ui.toggle_value(&mut st.outline, "O")
            .on_hover_text("Outline: only the segment's boundary shows");
        // The name last: long names run to the panel's edge without covering a control.
        let label = match value {
            Some(k) if k.layer > 0 => format!("{name} ({}:{})", k.layer, k.value),
            Some(k) => format!("{name} ({})", k.value),
            None => name.clone(),
        };
        ui.checkbox(&mut st.visible, label);
    });
    if only_this {
        only(&mut seg.styles, labels, row);
        return;
    }
    if st != before {
        match value {
            Some(k) => seg.styles.set(k, st),
            None => seg.styles.unlabelled = st,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::Segment;

    fn map() -> LabelMap {
        let seg = |value, name: &str, voxels| Segment {
            key: SegmentKey { layer: 0, value },
            name: name.into(),
            color: [1, 2, 3],
            voxels,
        };
        LabelMap {
            dims: [1, 1, 1],
            layers: vec![vec![0]],
            segments: vec![
                seg(1, "Spleen", 10),
                seg(2, "kidney_right", 5),
                seg(3, "kidney_left", 0),
                seg(4, "Liver", 7),
            ],
            path: PathBuf::from("x"),
        }
    }

    #[test]
    fn the_search_filters_names_by_substring_ignoring_case_and_lists_only_present_ones() {
        let m = map();
        use Row::*;
        assert_eq!(
            filter_rows(&m, ""),
            vec![Unlabelled, Segment(0), Segment(1), Segment(3)]
        );
        assert_eq!(filter_rows(&m, "KIDNEY"), vec![Segment(1)]);
        assert_eq!(filter_rows(&m, " li"), vec![Segment(3)]);
        assert_eq!(filter_rows(&m, "unlab"), vec![Unlabelled]);
        assert_eq!(filter_rows(&m, "lung"), vec![]);
    }

    #[test]
    fn only_hides_every_other_segment_and_the_unlabelled_voxels() {
        let m = map();
        let mut styles = Styles::default();
        only(&mut styles, &m, Row::Segment(1));
        assert!(!styles.unlabelled.visible);
        let shown: Vec<u16> = m
            .segments
            .iter()
            .filter(|s| styles.get(s.key).visible)
            .map(|s| s.key.value)
            .collect();
        assert_eq!(shown, vec![2]);
        set_visible(&mut styles, &m, &filter_rows(&m, ""), true);
        assert!(styles.unlabelled.visible && styles.get(m.segments[0].key).visible);
    }
}
