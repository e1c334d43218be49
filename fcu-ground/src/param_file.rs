//! Parameter files, read line by line by fcu-core's `parameters::file::lines`, the reader
//! `cargo pil serve --params` and `fcu-sim fly --params` use too (so each takes the files the
//! others take, and this command writes):
//!
//! - MAVProxy's `param save`: one `NAME VALUE` per line, the two separated by spaces, tabs or
//!   a comma (MAVProxy pads the name to 16 columns; fcu-core writes one space);
//! - QGroundControl's `.params`: `SYS<TAB>COMP<TAB>NAME<TAB>VALUE<TAB>TYPE`;
//! - `#` starts a comment, to the end of the line; blank lines are skipped; a UTF-8
//!   byte-order mark at the start is skipped;
//! - values are written as the shortest text that reads back as the same `f32`.
//!
//! A line that does not read, a name set twice, a name longer than MAVLink's 16 characters
//! and a value that is not a finite number are refused, each with its line; so is a radio
//! map (`RCMAP_*`) that is not a permutation ([`map_problem`]).

use std::collections::BTreeMap;
use std::fmt;

/// MAVLink's `param_id` holds at most 16 characters (fcu-core's reader refuses longer names).
pub use fcu_params::NAME_LEN;

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
    use fcu_params::file::{self, Problem};
    let mut entries: Vec<Entry> = Vec::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for read in file::lines(text) {
        let e = read.map_err(|e| FileError {
            line: e.line,
            message: match e.problem {
                Problem::NoValue { name } => format!("`{}` has no value (expected NAME VALUE)", echo(name)),
                Problem::Extra { extra } => {
                    format!("`{}` after the value (expected NAME VALUE, or SYS COMP NAME VALUE TYPE)", echo(extra))
                }
                Problem::NameTooLong { name } => format!("`{}` is longer than {NAME_LEN} characters, MAVLink's limit", echo(name)),
                Problem::NotANumber { name, value } => format!("{}: `{}` is not a number", echo(name), echo(value)),
                Problem::NotFinite { name } => format!("{}: the value is not a finite number", echo(name)),
            },
        })?;
        if let Some(first) = seen.insert(e.name.to_string(), e.line) {
            return Err(FileError { line: e.line, message: format!("{} is already set on line {first}", e.name) });
        }
        entries.push(Entry { line: e.line, name: e.name.to_string(), value: e.value });
    }
    Ok(entries)
}

/// The radio map the file makes over `board` (name to value; `None`: the file alone) is not
/// a permutation: the line to blame, with fcu-core's rule, as the board and every other
/// reader would refuse it. Checked before anything is sent: set one at a time, each entry
/// would swap with the function holding its input, and the map come out otherwise than the
/// file says, silently.
pub fn map_problem(entries: &[Entry], board: Option<&BTreeMap<String, f32>>) -> Option<FileError> {
    use fcu_params as parameters;
    // Not on the board, or not asked: NaN, which equals nothing.
    let mut values = [f32::NAN; parameters::COUNT];
    let mut lines = [0usize; parameters::COUNT];
    for (i, v) in values.iter_mut().enumerate() {
        if let Some(&b) = parameters::name(i).and_then(|n| board.and_then(|b| b.get(n))) {
            *v = b;
        }
    }
    for e in entries {
        if let Some(i) = parameters::index_of(e.name.as_bytes()) {
            values[i] = e.value;
            lines[i] = e.line;
        }
    }
    let line = parameters::file::repeated_map_line(&values, &lines)?;
    let name = entries.iter().find(|e| e.line == line).map_or("", |e| e.name.as_str());
    Some(FileError { line, message: format!("{name}: {}", parameters::RULE_RCMAP) })
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
    fcu_log::csv::echo(text)
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
    fn a_byte_order_mark_and_qgroundcontrol_files_read_as_mavproxy_ones() {
        let mavproxy = parse("ANG_RLL_P 5.5\nRC1_MIN 1000.25\n").unwrap();
        assert_eq!(parse("\u{feff}ANG_RLL_P 5.5\nRC1_MIN 1000.25\n").unwrap(), mavproxy);
        let qgc = "# Onboard parameters for Vehicle 1\n#\n# Vehicle-Id Component-Id Name Value Type\n1\t1\tANG_RLL_P\t5.5\t9\n\
                   1\t1\tRC1_MIN\t1000.25\t9\n";
        let got: Vec<(String, f32)> = parse(qgc).unwrap().into_iter().map(|e| (e.name, e.value)).collect();
        assert_eq!(got, [("ANG_RLL_P".to_string(), 5.5), ("RC1_MIN".to_string(), 1000.25)]);
        assert_eq!(parse("1 1 ANG_RLL_P 5\n").unwrap_err().line, 1);
    }

    #[test]
    fn a_radio_map_that_is_no_permutation_is_named_with_its_line() {
        let map = "RCMAP_ROLL 2\nRCMAP_PITCH 2\nRCMAP_THROTTLE 3\nRCMAP_YAW 4\n";
        let e = map_problem(&parse(map).unwrap(), None).unwrap();
        assert_eq!(e.to_string(), "line 2: RCMAP_PITCH: RCMAP: each input once");
        // One entry against the board's map.
        let board: BTreeMap<String, f32> = [("RCMAP_ROLL", 1.0), ("RCMAP_PITCH", 2.0), ("RCMAP_THROTTLE", 3.0), ("RCMAP_YAW", 4.0)]
            .iter()
            .map(|&(n, v)| (n.to_string(), v))
            .collect();
        let one = parse("ANG_RLL_P 5\nRCMAP_ROLL 2\n").unwrap();
        assert_eq!(map_problem(&one, None), None);
        assert_eq!(map_problem(&one, Some(&board)).unwrap().to_string(), "line 2: RCMAP_ROLL: RCMAP: each input once");
        let swap = parse("RCMAP_ROLL 2\nRCMAP_PITCH 1\n").unwrap();
        assert_eq!(map_problem(&swap, Some(&board)), None);
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
        use fcu_params as parameters;
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
