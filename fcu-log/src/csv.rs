//! A small CSV reader for the project's numeric files: header by name, every error names the
//! line (1-based, the header is line 1) and the column.
//!
//! Why not the `csv` crate: the files here are plain numeric tables (no quoting, no embedded
//! commas or newlines), and what the readers need beyond splitting is all project-specific:
//! a byte-order mark accepted, a size cap before and after decompression, duplicate or
//! backwards times refused, values that overflow f32 refused, and every message short and
//! printable with the offending field echoed and cut ([`echo`], [`short_number`]). The crate
//! reports record and byte positions, not the column by name, so those wrappers would stay
//! and only the `split(',')` would go; for that, a dependency (and its own error type to map
//! into these messages) is not worth it. `fuzz/` runs every reader on arbitrary bytes.

use std::fmt;

/// A CSV problem, with where it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvError {
    pub line: usize,
    pub message: String,
}

impl fmt::Display for CsvError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl std::error::Error for CsvError {}

/// The header of a CSV file: column names in order.
#[derive(Debug, Clone)]
pub struct Header {
    names: Vec<String>,
}

impl Header {
    pub fn parse(line: &str) -> Header {
        Header { names: line.trim_end_matches('\r').split(',').map(|s| s.trim().to_string()).collect() }
    }

    /// The index of each required column, or an error naming the missing one.
    pub fn indices<const N: usize>(&self, wanted: [&str; N]) -> Result<[usize; N], CsvError> {
        let mut out = [0usize; N];
        for (o, w) in out.iter_mut().zip(wanted) {
            *o = self
                .names
                .iter()
                .position(|n| n == w)
                .ok_or_else(|| CsvError { line: 1, message: format!("missing column `{w}` in the header") })?;
        }
        Ok(out)
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }
}

/// One data row, split, with its line number for messages.
pub struct Row<'a> {
    pub line: usize,
    fields: Vec<&'a str>,
    names: &'a Header,
}

impl<'a> Row<'a> {
    pub fn split(line_no: usize, text: &'a str, header: &'a Header) -> Result<Row<'a>, CsvError> {
        let fields: Vec<&str> = text.trim_end_matches('\r').split(',').map(str::trim).collect();
        if fields.len() != header.len() {
            return Err(CsvError { line: line_no, message: format!("expected {} columns, found {}", header.len(), fields.len()) });
        }
        Ok(Row { line: line_no, fields, names: header })
    }

    fn raw(&self, idx: usize) -> Result<(&str, &str), CsvError> {
        let name = self.names.names.get(idx).map(String::as_str).unwrap_or("?");
        let v = self.fields.get(idx).copied().ok_or_else(|| CsvError { line: self.line, message: format!("missing column `{name}`") })?;
        Ok((name, v))
    }

    /// Parse a column as `T`, or an error naming the line, the column and the text.
    pub fn get<T: std::str::FromStr>(&self, idx: usize) -> Result<T, CsvError> {
        let (name, v) = self.raw(idx)?;
        v.parse::<T>().map_err(|_| CsvError {
            line: self.line,
            message: format!("column `{}`: `{}` is not a valid {}", echo(name), echo(v), short_type_name::<T>()),
        })
    }

    /// A finite f32: `inf`, `nan` and numbers beyond f32's range (which parse as infinity)
    /// are refused, since a comparison against them could not fail.
    pub fn finite_f32(&self, idx: usize) -> Result<f32, CsvError> {
        let v: f32 = self.get(idx)?;
        if v.is_finite() {
            Ok(v)
        } else {
            let (name, text) = self.raw(idx)?;
            Err(CsvError { line: self.line, message: format!("column `{}`: `{}` is not a finite f32", echo(name), echo(text)) })
        }
    }

    /// Parse a 0/1 flag column.
    pub fn flag(&self, idx: usize) -> Result<bool, CsvError> {
        let (name, v) = self.raw(idx)?;
        match v {
            "0" => Ok(false),
            "1" => Ok(true),
            _ => Err(CsvError { line: self.line, message: format!("column `{name}`: `{v}` is not 0 or 1") }),
        }
    }
}

/// A field as it may appear in a message: invisible and control characters escaped, and
/// no more than 40 characters of it.
pub fn echo(field: &str) -> String {
    const MAX: usize = 40;
    let escaped: String = field.chars().flat_map(char::escape_debug).collect();
    if escaped.chars().count() > MAX {
        escaped.chars().take(MAX - 1).chain(std::iter::once('…')).collect()
    } else {
        escaped
    }
}

/// A number as it may appear in a message: plain when it is of a readable size, else in
/// scientific notation (1e308 would otherwise print as 309 digits).
pub fn short_number(v: f64) -> String {
    if v == 0.0 || (1e-3..1e7).contains(&v.abs()) {
        let s = format!("{v:.6}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.3e}")
    }
}

/// Decompressed text larger than this is refused (the largest real input is a few MB).
pub const MAX_TEXT_BYTES: u64 = 256 * 1024 * 1024;

fn short_type_name<T>() -> &'static str {
    let n = std::any::type_name::<T>();
    n.rsplit("::").next().unwrap_or(n)
}

/// Read a text file, gunzipping it when it is gzip-compressed (recognised by its magic bytes,
/// whatever its name).
pub fn read_text(path: &std::path::Path) -> std::io::Result<String> {
    use std::io::Read;
    let bytes = std::fs::read(path)?;
    let bytes = if bytes.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::new();
        // One byte past the cap tells an oversized stream (a few MB of zeros can expand to GB).
        flate2::read::MultiGzDecoder::new(bytes.as_slice()).take(MAX_TEXT_BYTES + 1).read_to_end(&mut out)?;
        if out.len() as u64 > MAX_TEXT_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("decompresses to more than {} MiB: not an input of this program", MAX_TEXT_BYTES >> 20),
            ));
        }
        out
    } else {
        bytes
    };
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = e.as_bytes().get(..at).map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count()) + 1;
        std::io::Error::new(std::io::ErrorKind::InvalidData, format!("line {line}: not UTF-8 text"))
    })?;
    // A UTF-8 byte-order mark is not part of the first header.
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// Iterate the data lines of a CSV text (skipping the header and blank lines), with their
/// 1-based line numbers.
pub fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().skip(1).map(|(i, l)| (i + 1, l)).filter(|(_, l)| !l.trim().is_empty())
}

/// Format an f32 like C's `printf("%.9g")`, which round-trips binary32 exactly.
pub fn fmt_g9(v: f32) -> String {
    if v.is_nan() {
        return "nan".into();
    }
    if v.is_infinite() {
        return if v > 0.0 { "inf".into() } else { "-inf".into() };
    }
    if v == 0.0 {
        return if v.is_sign_negative() { "-0".into() } else { "0".into() };
    }
    let e = format!("{:.8e}", f64::from(v));
    let (mantissa, exp) = e.split_once('e').unwrap_or((&e, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if (-4..9).contains(&exp) {
        let decimals = (8 - exp).max(0) as usize;
        let s = format!("{:.*}", decimals, f64::from(v));
        trim_zeros(&s)
    } else {
        let m = trim_zeros(mantissa);
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{m}e{sign}{:02}", exp.abs())
    }
}

fn trim_zeros(s: &str) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn g9_matches_c_printf() {
        assert_eq!(fmt_g9(0.998_307_17), "0.998307168");
        assert_eq!(fmt_g9(1.0), "1");
        assert_eq!(fmt_g9(-0.0), "-0");
        assert_eq!(fmt_g9(800.0), "800");
        assert_eq!(fmt_g9("1.98177537e+19".parse().unwrap()), "1.98177537e+19");
        assert_eq!(fmt_g9("9.99999997e-07".parse().unwrap()), "9.99999997e-07");
        assert_eq!(fmt_g9("0.000998304575".parse().unwrap()), "0.000998304575");
        assert_eq!(fmt_g9("-150.697479".parse().unwrap()), "-150.697479");
        assert_eq!(fmt_g9(f32::NAN), "nan");
    }

    #[test]
    fn errors_name_the_line_and_column() {
        let h = Header::parse("a,b");
        let r = Row::split(7, "1,x", &h).unwrap();
        let e = r.get::<i32>(1).unwrap_err();
        assert_eq!(e.to_string(), "line 7: column `b`: `x` is not a valid i32");
        let e = Row::split(8, "1", &h).err().unwrap();
        assert_eq!(e.to_string(), "line 8: expected 2 columns, found 1");
        assert!(h.indices(["c"]).is_err());
    }

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(short_number(1e308), "1.000e308");
        assert_eq!(short_number(2.5), "2.5");
        assert_eq!(short_number(0.0035), "0.0035");
    }

    #[test]
    fn messages_escape_invisible_characters_and_cut_long_fields() {
        assert_eq!(echo("a\u{0}b"), "a\\0b");
        assert_eq!(echo("\u{feff}t_s"), "\\u{feff}t_s");
        let long = "9".repeat(3_000_000);
        assert!(echo(&long).chars().count() <= 40);
        let h = Header::parse("x");
        let r = Row::split(2, "inf", &h).unwrap();
        assert!(r.finite_f32(0).is_err());
        let r = Row::split(2, "-1e39", &h).unwrap();
        assert!(r.finite_f32(0).unwrap_err().to_string().contains("not a finite f32"));
    }
}
