//! One G-code reader for the simulator, the simulated GRBL and the sender:
//! a line read as GRBL 1.1's protocol and parser read it. Comments, spaces,
//! control characters and the block-delete '/' are dropped, letters taken
//! in any case; words are read in order, each a letter and a number, until
//! one is not: the line then carries GRBL's code for that word (1, no
//! letter; 2, no number) and what GRBL would refuse first is for the modal
//! state to decide, word by word as GRBL does.

use crate::bail;
use crate::error::Result;

/// One parsed line: its 1-based line number in the file and its words.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    pub number: usize,
    pub words: Vec<(char, f64)>,
    /// Text of the comments on the line (without delimiters).
    pub comments: Vec<String>,
    /// GRBL's error for the line, if reading stopped: 11 (longer than
    /// its line buffer, no word read), or for the word after the last one
    /// read: 1 (expected a letter) or 2 (bad number).
    pub bad: Option<u32>,
}

/// GRBL's protocol loop reading a line byte by byte (protocol.c): spaces,
/// control characters, '/' and comments dropped, letters upper-cased, at
/// most `LINE_MAX` characters kept (then the line overflows: error:11).
/// Bytes are kept one char each (Latin-1), as GRBL keeps them.
#[derive(Clone, Debug, Default)]
pub struct LineFilter {
    held: Vec<u8>,
    paren: bool,
    semicolon: bool,
    overflow: bool,
}

impl LineFilter {
    /// One byte; at a line's end ('\n' or '\r', each its own end), the
    /// line as GRBL's buffer holds it, or error:11.
    pub fn push(&mut self, c: u8) -> Option<std::result::Result<String, u32>> {
        if c == b'\n' || c == b'\r' {
            let line = self.held.iter().map(|&b| b as char).collect();
            let overflow = self.overflow;
            *self = LineFilter::default();
            return Some(if overflow { Err(11) } else { Ok(line) });
        }
        if self.paren || self.semicolon || self.overflow {
            if c == b')' {
                self.paren = false;
            }
            return None;
        }
        match c {
            c if c <= b' ' || c == b'/' => {}
            b'(' => self.paren = true,
            b';' => self.semicolon = true,
            _ if self.held.len() >= LINE_MAX => self.overflow = true,
            c => self.held.push(c.to_ascii_uppercase()),
        }
        None
    }
}

/// Remove comments and whitespace: what GRBL's line buffer will hold
/// (not cut at its length).
pub fn strip(line: &str) -> String {
    split(line).0
}

/// What GRBL's line buffer holds and the comments' texts.
fn split(line: &str) -> (String, Vec<String>) {
    let mut out = String::with_capacity(line.len());
    let mut comments: Vec<String> = Vec::new();
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            // GRBL ends a '(' comment at ')' or the line's end
            '(' => comments.push(chars.by_ref().take_while(|&d| d != ')').collect()),
            ';' => {
                comments.push(chars.by_ref().collect());
                break;
            }
            '/' => {}
            c if c <= ' ' => {}
            c => out.push(c.to_ascii_uppercase()),
        }
    }
    for c in &mut comments {
        *c = c.trim().to_string();
    }
    (out, comments)
}

/// GRBL's read_float: an optional sign, then digits with at most one
/// point, at least one digit; where the number ends. The value is GRBL's
/// float: the first 8 digits as an integer, scaled by tens in single
/// precision as GRBL scales them, so that every later test (an integer
/// command, a negative word, a radius) sees the number GRBL sees.
pub fn read_number(b: &[u8], mut i: usize) -> Option<(f64, usize)> {
    let negative = match b.get(i) {
        Some(b'-') => {
            i += 1;
            true
        }
        Some(b'+') => {
            i += 1;
            false
        }
        _ => false,
    };
    let (mut int, mut exp, mut digits, mut point) = (0u32, 0i32, 0, false);
    while i < b.len() {
        match b[i] {
            c @ b'0'..=b'9' => {
                digits += 1;
                if digits <= 8 {
                    if point {
                        exp -= 1;
                    }
                    int = int * 10 + (c - b'0') as u32;
                } else if !point {
                    exp += 1; // digits past the eighth are dropped
                }
            }
            b'.' if !point => point = true,
            _ => break,
        }
        i += 1;
    }
    if digits == 0 {
        return None;
    }
    // each step in double precision, kept as a float, as C does it
    let scale = |v: f32, by: f64| (v as f64 * by) as f32;
    let mut v = int as f32;
    if v != 0.0 {
        while exp <= -2 {
            v = scale(v, 0.01);
            exp += 2;
        }
        if exp < 0 {
            v = scale(v, 0.1);
        }
        while exp > 0 {
            v = scale(v, 10.0);
            exp -= 1;
        }
    }
    Some((if negative { -v } else { v } as f64, i))
}

/// The longest line GRBL's line buffer holds, after comments and spaces
/// are dropped (LINE_BUFFER_SIZE 80, one for the terminator); a longer
/// one is refused whole with error:11.
pub const LINE_MAX: usize = 79;

/// Read one line (`number` names it).
pub fn parse_line(text: &str, number: usize) -> Line {
    let (stripped, comments) = split(text);
    let b = stripped.as_bytes();
    let mut words = Vec::new();
    let mut bad = (b.len() > LINE_MAX).then_some(11);
    let mut i = if bad.is_some() { b.len() } else { 0 };
    while i < b.len() {
        let letter = b[i];
        if !letter.is_ascii_uppercase() {
            bad = Some(1);
            break;
        }
        match read_number(b, i + 1) {
            Some((v, next)) => {
                words.push((letter as char, v));
                i = next;
            }
            None => {
                bad = Some(2);
                break;
            }
        }
    }
    Line {
        number,
        words,
        comments,
        bad,
    }
}

/// Parse a whole program and fold it through GRBL's modal state; the
/// first line GRBL would refuse is the error, with its code.
pub fn parse(text: &str) -> Result<Vec<Line>> {
    let mut m = super::modal::Modal::new(glam::DVec3::ZERO);
    let mut out = Vec::new();
    for (k, l) in text.lines().enumerate() {
        let line = parse_line(l, k + 1);
        if let Err(r) = m.apply(&line) {
            bail!(
                "line {}: error:{} ({}) in '{}'",
                k + 1,
                r.code,
                r.what,
                l.trim()
            );
        }
        out.push(line);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_comments_case_and_spacing() {
        let l = parse_line("n10 g1x1.5 Y -2 (cut) z-0.25 F 600 ; tail", 3);
        assert_eq!(
            l.words,
            vec![
                ('N', 10.0),
                ('G', 1.0),
                ('X', 1.5),
                ('Y', -2.0),
                ('Z', -0.25),
                ('F', 600.0)
            ]
        );
        assert_eq!(l.comments, vec!["cut", "tail"]);
        assert_eq!(strip("G1 X1 (a b) Y2 ; c"), "G1X1Y2");
    }

    #[test]
    fn errors_name_the_line() {
        assert!(parse("G0 X1\nG1 Q5 F1\n")
            .unwrap_err()
            .0
            .contains("line 2: error:20"));
        assert!(parse("G0 X1\n\nG1 X2\n")
            .unwrap_err()
            .0
            .contains("line 3: error:22"));
        // GRBL ends a comment at the line's end
        assert_eq!(parse_line("G1 X1 (open", 1).words.len(), 2);
        assert!(parse("G1 X(oops\n")
            .unwrap_err()
            .0
            .contains("line 1: error:2"));
        assert!(parse("G1 X--1\n")
            .unwrap_err()
            .0
            .contains("line 1: error:2"));
        assert!(parse("G1 X1 %\n")
            .unwrap_err()
            .0
            .contains("line 1: error:1"));
        assert!(parse("M6\n").unwrap_err().0.contains("M6"));
    }
}
