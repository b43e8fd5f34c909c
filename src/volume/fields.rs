//! Fixed-size numbers and text at byte offsets of a binary header, in one byte order:
//! what the NIfTI-2 and Analyze 7.5 parsers read their fields with.

/// A header's bytes and their byte order.
#[derive(Debug, Clone, Copy)]
pub struct Fields<'a> {
    buf: &'a [u8],
    little_endian: bool,
}

macro_rules! number_at {
    ($($name:ident: $t:ty),* $(,)?) => {
        $(
            #[doc = concat!("The `", stringify!($t), "` at byte `at`.")]
            pub fn $name(&self, at: usize) -> $t {
                let b = self.array(at);
                if self.little_endian { <$t>::from_le_bytes(b) } else { <$t>::from_be_bytes(b) }
            }
        )*
    };
}

impl<'a> Fields<'a> {
    pub fn new(buf: &'a [u8], little_endian: bool) -> Self {
        Fields { buf, little_endian }
    }

    fn array<const N: usize>(&self, at: usize) -> [u8; N] {
        std::array::from_fn(|k| self.buf[at + k])
    }

    number_at!(i16: i16, i32: i32, i64: i64, f32: f32, f64: f64);

    /// `n` bytes at `at` as text, up to the first NUL, trimmed.
    pub fn text(&self, at: usize, n: usize) -> String {
        let b = &self.buf[at..at + n];
        let end = b.iter().position(|&c| c == 0).unwrap_or(n);
        String::from_utf8_lossy(&b[..end]).trim().to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::Fields;

    #[test]
    fn both_byte_orders() {
        let buf = [0x01, 0x02, 0x03, 0x04, b'a', b'b', 0, b'c'];
        assert_eq!(Fields::new(&buf, true).i16(0), 0x0201);
        assert_eq!(Fields::new(&buf, false).i16(0), 0x0102);
        assert_eq!(Fields::new(&buf, false).i32(0), 0x0102_0304);
        assert_eq!(Fields::new(&buf, true).text(4, 4), "ab");
    }
}
