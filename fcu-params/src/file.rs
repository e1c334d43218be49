//! The one reader of parameter files: `fcu-sim fly --params`, `cargo pil serve --params`
//! (through [`apply_file`](super::apply_file)) and `fcu-ground params push/diff` read every
//! line through [`lines`], so a file means the same to each.
//!
//! Two formats, line by line (they may even be mixed):
//!
//! - MAVProxy's `param save`: `NAME VALUE`, separated by spaces, tabs or a comma (MAVProxy
//!   pads the name to 16 columns; fcu-core writes one space);
//! - QGroundControl's `.params`: `SYS COMP NAME VALUE TYPE`, tab-separated (the vehicle's
//!   system and component ids and MAVLink's `MAV_PARAM_TYPE`, whole numbers; every value
//!   here is read as the `f32` it names).
//!
//! `#` starts a comment to the end of the line (QGroundControl's header is comments), blank
//! lines are skipped, and a UTF-8 byte-order mark at the start of the file is skipped
//! (Windows editors write one; kept, it would make the first name unknown, invisibly).

use super::NAME_LEN;

/// One parameter line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line<'a> {
    /// 1-based line number in the file.
    pub line: usize,
    pub name: &'a str,
    /// A finite `f32`: the text read to the nearest, as the board takes it.
    pub value: f32,
}

/// What is wrong with a line, with the words at fault for a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Problem<'a> {
    /// A name and nothing else.
    NoValue {
        name: &'a str,
    },
    /// Words after the value that do not make a QGroundControl line (the first of them).
    Extra {
        extra: &'a str,
    },
    NotANumber {
        name: &'a str,
        value: &'a str,
    },
    NotFinite {
        name: &'a str,
    },
    /// Longer than MAVLink's 16-character `param_id`.
    NameTooLong {
        name: &'a str,
    },
}

impl Problem<'_> {
    /// The rule, short enough for a status line (at most [`RULE_LEN`](super::RULE_LEN)).
    pub fn rule(&self) -> &'static str {
        match self {
            Problem::NoValue { .. } | Problem::Extra { .. } => RULE_LINE,
            Problem::NotANumber { .. } => RULE_NOT_A_NUMBER,
            Problem::NotFinite { .. } => super::RULE_NOT_FINITE,
            Problem::NameTooLong { .. } => RULE_NAME_TOO_LONG,
        }
    }
}

pub const RULE_LINE: &str = "expected NAME VALUE";
pub const RULE_NOT_A_NUMBER: &str = "value is not a number";
pub const RULE_NAME_TOO_LONG: &str = "name longer than 16 characters";
pub const RULE_TWICE: &str = "set twice in the file";

/// A line that cannot be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LineError<'a> {
    /// 1-based.
    pub line: usize,
    pub problem: Problem<'a>,
}

/// The parameter lines of `text`, in file order, each read or refused with its line.
pub fn lines(text: &str) -> impl Iterator<Item = Result<Line<'_>, LineError<'_>>> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines().enumerate().filter_map(|(n, raw)| read_line(n + 1, raw).transpose())
}

/// One line: `None` when it holds no parameter (blank, or only a comment).
fn read_line(line: usize, raw: &str) -> Result<Option<Line<'_>>, LineError<'_>> {
    let err = |problem| LineError { line, problem };
    let content = raw.split('#').next().unwrap_or("");
    let mut words = content.split(|c: char| c.is_whitespace() || c == ',').filter(|w| !w.is_empty());
    let Some(first) = words.next() else { return Ok(None) };
    let Some(second) = words.next() else { return Err(err(Problem::NoValue { name: first })) };
    let (name, value) = match (words.next(), words.next(), words.next(), words.next()) {
        (None, ..) => (first, second),
        // QGroundControl's: SYS COMP NAME VALUE TYPE, the three numbers whole.
        (Some(name), Some(value), Some(kind), None) if [first, second, kind].iter().all(|w| w.parse::<u8>().is_ok()) => (name, value),
        (Some(extra), ..) => return Err(err(Problem::Extra { extra })),
    };
    if name.len() > NAME_LEN {
        return Err(err(Problem::NameTooLong { name }));
    }
    let value: f32 = value.parse().map_err(|_| err(Problem::NotANumber { name, value }))?;
    if !value.is_finite() {
        return Err(err(Problem::NotFinite { name }));
    }
    Ok(Some(Line { line, name, value }))
}

/// The line to blame for a radio map that is not a permutation: `values` the set a file
/// makes (table order), `lines` the line each value came from (0: not from the file). Of the
/// `RCMAP_*` entries that name an input another one names, the one on the latest line.
pub fn repeated_map_line(values: &[f32; super::COUNT], lines: &[usize; super::COUNT]) -> Option<usize> {
    let maps = || super::TABLE.iter().zip(values.iter().zip(lines)).filter(|(p, _)| matches!(p.field, super::Field::RcMap(_)));
    let repeated = |v: f32| maps().filter(|(_, (&w, _))| w == v).count() > 1;
    maps().filter(|(_, (&v, _))| repeated(v)).map(|(_, (_, &line))| line).max().filter(|&line| line > 0)
}
