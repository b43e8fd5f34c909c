//! A walk over a DICOM file's elements that refuses lengths the file cannot hold,
//! before dicom-rs reserves memory for them.

/// Checks, before dicom-rs sees a file, that no element claims more bytes than the
/// file holds: dicom-rs reserves an element's declared length before reading it, so a
/// 1 KiB file claiming a 4 GiB element would make it allocate 4 GiB (found by fuzzing).
/// Walks the meta group and, for little/big endian explicit and implicit VR, the data
/// set with its sequences and items. Returns the first impossible claim; stops quietly
/// where it cannot follow the encoding (deflate, an unknown VR), leaving those to
/// dicom-rs.
pub fn check_declared_lengths(bytes: &[u8]) -> Result<(), String> {
    let Some(body) = bytes.get(132..).filter(|_| has_dicm_magic(bytes)) else {
        return Ok(());
    };
    let mut w = Walker {
        b: body,
        explicit: true,
        little: true,
    };
    // The meta group is explicit little endian; then the data set's own encoding.
    let mut at = 0usize;
    let mut ts_uid = String::new();
    while at + 8 <= body.len() && u16::from_le_bytes([body[at], body[at + 1]]) == 0x0002 {
        let next = match w.element(at, body.len(), 0, false)? {
            Some(next) => next,
            None => return Ok(()),
        };
        if u16::from_le_bytes([body[at + 2], body[at + 3]]) == 0x0010 {
            ts_uid = String::from_utf8_lossy(&body[at + 8..next]).into_owned();
        }
        at = next;
    }
    let (explicit, little) = match ts_uid.trim_end_matches(['\0', ' ']) {
        "1.2.840.10008.1.2" => (false, true),
        "1.2.840.10008.1.2.2" => (true, false),
        "1.2.840.10008.1.2.1.99" => return Ok(()), // deflated: not followed
        _ => (true, true),
    };
    w.explicit = explicit;
    w.little = little;
    w.walk(at, body.len(), 0, false).map(|_| ())
}

struct Walker<'a> {
    b: &'a [u8],
    explicit: bool,
    little: bool,
}

const LONG_VRS: [&[u8; 2]; 13] = [
    b"OB", b"OD", b"OF", b"OL", b"OV", b"OW", b"SQ", b"SV", b"UC", b"UN", b"UR", b"UT", b"UV",
];

impl Walker<'_> {
    fn u16(&self, at: usize) -> u16 {
        let v = [self.b[at], self.b[at + 1]];
        if self.little {
            u16::from_le_bytes(v)
        } else {
            u16::from_be_bytes(v)
        }
    }

    fn u32(&self, at: usize) -> u32 {
        let v = [self.b[at], self.b[at + 1], self.b[at + 2], self.b[at + 3]];
        if self.little {
            u32::from_le_bytes(v)
        } else {
            u32::from_be_bytes(v)
        }
    }

    /// Elements (or, with `fragments`, the items of encapsulated pixel data) from `at`
    /// to `end` or to a delimiter: `Ok(Some(pos))` after them, `Ok(None)` where the walk
    /// cannot follow.
    fn walk(
        &self,
        mut at: usize,
        end: usize,
        depth: usize,
        fragments: bool,
    ) -> Result<Option<usize>, String> {
        if depth > 32 {
            return Ok(None);
        }
        while at + 8 <= end {
            let (g, e) = (self.u16(at), self.u16(at + 2));
            if g == 0xfffe && (e == 0xe00d || e == 0xe0dd) {
                return Ok(Some(at + 8)); // item / sequence delimiter
            }
            match self.element(at, end, depth, fragments)? {
                Some(next) => at = next,
                None => return Ok(None),
            }
        }
        Ok(Some(at))
    }

    fn element(
        &self,
        at: usize,
        end: usize,
        depth: usize,
        fragments: bool,
    ) -> Result<Option<usize>, String> {
        if at + 8 > end {
            return Ok(None);
        }
        let (g, e) = (self.u16(at), self.u16(at + 2));
        let item = g == 0xfffe && e == 0xe000;
        if fragments && !item {
            return Ok(None);
        }
        let (len, head, vr) = if g == 0xfffe {
            (self.u32(at + 4), 8, None)
        } else if self.explicit {
            let vr = [self.b[at + 4], self.b[at + 5]];
            if !vr.iter().all(u8::is_ascii_uppercase) {
                return Ok(None);
            }
            if LONG_VRS.contains(&&vr) {
                if at + 12 > end {
                    return Ok(None);
                }
                (self.u32(at + 8), 12, Some(vr))
            } else {
                (u32::from(self.u16(at + 6)), 8, Some(vr))
            }
        } else {
            (self.u32(at + 4), 8, None)
        };
        let start = at + head;
        let pixel_data = (g, e) == (0x7fe0, 0x0010);
        if len == u32::MAX {
            // Undefined length: encapsulated pixel data (fragments), a sequence, or an
            // item of a sequence (elements).
            return self.walk(start, end, depth + 1, pixel_data);
        }
        let len = len as usize;
        if len > end.saturating_sub(start) {
            return Err(format!(
                "element ({g:04X},{e:04X}) claims {len} bytes but only {} remain in the file: truncated or damaged",
                end.saturating_sub(start)
            ));
        }
        let sequence = vr == Some(*b"SQ");
        if sequence || (item && !fragments) {
            self.walk(start, start + len, depth + 1, false)?;
        }
        Ok(Some(start + len))
    }
}

/// Whether `head` (a file's first bytes) carries the DICOM preamble magic.
pub fn has_dicm_magic(head: &[u8]) -> bool {
    head.get(128..132) == Some(b"DICM")
}
