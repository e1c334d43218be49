//! Parameter files in MAVProxy's `param save` format, read and written as fcu-core's
//! `parameters::apply_file` and `parameters::write_file` do (so `cargo pil serve --params` and
//! `fcu-sim fly --params` take the files this command writes, and the other way round):
//!
//! - one `NAME VALUE` per line, the two separated by spaces, tabs or a comma (MAVProxy pads the
//!   name to 16 columns; fcu-core writes one space);
//! - `#` starts a comment, to the end of the line; blank lines are skipped;
//! - values are written as the shortest text that reads back as the same `f32`.
//!
//! This reader is stricter than fcu-core's in what a ground tool should not guess: a name set
//! twice, a name longer than MAVLink's 16 characters and a value that is not a finite number
//! are refused, each with its line.

use std::collections::BTreeMap;
use std::fmt;

/// MAVLink's `param_id` holds at most 16 characters.
pub const NAME_LEN: usize = 16;

/// One `NAME VALUE` line.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// 1-based line number in the file.
    pub line: usize,
    pub name: String,
    pub value: f32,
}

/// A file problem, with its line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileError {
    pub line: usize,
    pub message: String,
}

impl fmt::Display for FileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

/// Reads a parameter file, in file order.
pub fn parse(text: &str) -> Result<Vec<Entry>, FileError> {
    let mut entries: Vec<Entry> = Vec::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for (n, raw) in text.lines().enumerate() {
        let line = n + 1;
        let err = |message: String| FileError { line, message };
        let content = raw.split('#').next().unwrap_or("");
        let mut words = content.split(|c: char| c.is_whitespace() || c == ',').filter(|w| !w.is_empty());
        let (Some(name), value, extra) = (words.next(), words.next(), words.next()) else { continue };
        let Some(value) = value else {
            return Err(err(format!("`{}` has no value (expected NAME VALUE)", echo(name))));
        };
        if let Some(extra) = extra {
            return Err(err(format!("`{}` after the value (expected NAME VALUE)", echo(extra))));
        }
        if name.len() > NAME_LEN {
            return Err(err(format!("`{}` is longer than {NAME_LEN} characters, MAVLink's limit", echo(name))));
        }
        let value: f32 = value.parse().map_err(|_| err(format!("{name}: `{}` is not a number", echo(value))))?;
        if !value.is_finite() {
            return Err(err(format!("{name}: the value is not a finite number")));
        }
        if let Some(first) = seen.insert(name.to_string(), line) {
            return Err(err(format!("{name} is already set on line {first}")));
        }
        entries.push(Entry { line, name: name.to_string(), value });
    }
    Ok(entries)
}

/// Writes `params` (name, value) in the given order, one `NAME VALUE` line each.
pub fn write(params: &[(String, f32)]) -> String {
    let mut out = String::new();
    for (name, value) in params {
        out.push_str(name);
        out.push(' ');
        out.push_str(&value.to_string());
        out.push('\n');
    }
    out
}

/// How a file's entry compares with the board.
#[derive(Clone, Debug, PartialEq)]
pub enum Difference {
    /// The board holds another value.
    Value { line: usize, name: String, file: f32, board: f32 },
    /// The board has no parameter of that name.
    Unknown { line: usize, name: String },
}

impl fmt::Display for Difference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Difference::Value { line, name, file, board } => write!(f, "{name}: file {file} (line {line}), board {board}"),
            Difference::Unknown { line, name } => write!(f, "{name} (line {line}): the board has no such parameter"),
        }
    }
}

/// The entries of `file` that differ from `board` (name → value), in file order. Values are
/// compared as `f32`, exactly: the file's text read to the nearest `f32`, as the board would
/// take it.
pub fn diff(file: &[Entry], board: &BTreeMap<String, f32>) -> Vec<Difference> {
    file.iter()
        .filter_map(|e| match board.get(&e.name) {
            None => Some(Difference::Unknown { line: e.line, name: e.name.clone() }),
            Some(&b) if b != e.value => Some(Difference::Value { line: e.line, name: e.name.clone(), file: e.value, board: b }),
            Some(_) => None,
        })
        .collect()
}

/// A piece of a line as it may appear in a message: control characters escaped, cut at 40.
fn echo(text: &str) -> String {
    fcu_testkit::csv::echo(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mavproxy_and_fcu_core_layouts_read_alike() {
        let text = "# saved by MAVProxy\nRC1_MIN          1100.000000\nATT_P\t4.5\n\nRATE_P,0.0125 # tuned\n   \n";
        let entries = parse(text).unwrap();
        let got: Vec<(usize, &str, f32)> = entries.iter().map(|e| (e.line, e.name.as_str(), e.value)).collect();
        assert_eq!(got, vec![(2, "RC1_MIN", 1100.0), (3, "ATT_P", 4.5), (5, "RATE_P", 0.0125)]);
    }

    #[test]
    fn every_bad_line_is_named() {
        let line_of = |text: &str| parse(text).unwrap_err();
        let e = line_of("A 1\nB\n");
        assert_eq!(e.line, 2);
        assert!(e.message.contains("no value"), "{e}");
        let e = line_of("A 1 2\n");
        assert_eq!((e.line, e.message.contains("after the value")), (1, true), "{e}");
        let e = line_of("A 1\n\nB x1\n");
        assert_eq!(e.to_string(), "line 3: B: `x1` is not a number");
        let e = line_of("A nan\n");
        assert!(e.message.contains("not a finite number"), "{e}");
        let e = line_of("A 1e39\n");
        assert!(e.message.contains("not a finite number"), "{e}");
        let e = line_of("ABCDEFGHIJKLMNOPQ 1\n");
        assert!(e.message.contains("longer than 16"), "{e}");
        let e = line_of("A 1\nB 2\nA 3\n");
        assert_eq!(e.to_string(), "line 3: A is already set on line 1");
        // Sixteen characters is MAVLink's whole param_id: taken.
        assert_eq!(parse("ABCDEFGHIJKLMNOP 1").unwrap().len(), 1);
    }

    #[test]
    fn written_values_read_back_bit_for_bit() {
        let params: Vec<(String, f32)> = [("A", 0.1f32), ("B", 1.0e-7), ("C", 1500.25), ("D", -3.0), ("E", f32::MAX), ("F", 0.012_345_679)]
            .iter()
            .map(|&(n, v)| (n.to_string(), v))
            .collect();
        let back = parse(&write(&params)).unwrap();
        for ((name, value), e) in params.iter().zip(&back) {
            assert_eq!((&e.name, e.value.to_bits()), (name, value.to_bits()));
        }
    }

    #[test]
    fn the_format_agrees_with_fcu_core() {
        use fcu_core::parameters;
        // What fcu-core writes (and `cargo pil serve --params` reads) parses here, value for value.
        let mut cfg = fcu_core::Config::default();
        parameters::set_by_name(&mut cfg, b"RC1_MIN", 1050.0, false).unwrap();
        let mut core_text = String::new();
        parameters::write_file(&mut core_text, &cfg).unwrap();
        let entries = parse(&core_text).unwrap();
        assert_eq!(entries.len(), parameters::count());
        for (i, e) in entries.iter().enumerate() {
            assert_eq!(Some(e.name.as_str()), parameters::name(i));
            assert_eq!(Some(e.value.to_bits()), parameters::value(&cfg, i).map(f32::to_bits), "{}", e.name);
        }
        // And what this module writes, fcu-core reads back to the same configuration.
        let pairs: Vec<(String, f32)> = entries.iter().map(|e| (e.name.clone(), e.value)).collect();
        let ours = write(&pairs);
        assert_eq!(ours, core_text);
        let read = parameters::apply_file(&fcu_core::Config::default(), &ours).unwrap();
        assert_eq!(parameters::values(&read), parameters::values(&cfg));
    }

    #[test]
    fn diff_names_changed_and_unknown_entries_only() {
        let file = parse("A 1\nB 2.5\nC 3\n").unwrap();
        let board: BTreeMap<String, f32> = [("A".to_string(), 1.0), ("B".to_string(), 2.0), ("D".to_string(), 4.0)].into();
        let d = diff(&file, &board);
        assert_eq!(
            d,
            vec![Difference::Value { line: 2, name: "B".into(), file: 2.5, board: 2.0 }, Difference::Unknown { line: 3, name: "C".into() },]
        );
        assert_eq!(d[0].to_string(), "B: file 2.5 (line 2), board 2");
        let same = parse("A 1.0\nB 2\n").unwrap();
        assert!(diff(&same, &board).is_empty());
        // One f32 step apart is a difference.
        let next = f32::from_bits(2.0f32.to_bits() + 1);
        let close = parse(&format!("B {next}")).unwrap();
        assert_eq!(diff(&close, &board).len(), 1);
    }
}
