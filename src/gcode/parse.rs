//! One G-code reader for the simulator and the sender: words, comments and
//! line numbers of the GRBL 1.1 subset relievo speaks, any case and spacing.

use crate::bail;
use crate::error::Result;

/// One parsed line: its 1-based line number in the file and its words.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    pub number: usize,
    pub words: Vec<(char, f64)>,
    /// Text of the comments on the line (without delimiters).
    pub comments: Vec<String>,
}

/// The G codes relievo reads: motion, dwell, the arc planes, units,
/// distance modes, feed per minute, and what other CAM programs' GRBL
/// posts put in their preambles with no effect here (G40 cutter
/// compensation off, G49 tool length offset off while none is set, G54
/// while its offset is zero, G61 exact path, G80 motion off, G91.1).
const G_CODES: [f64; 19] = [
    0.0, 1.0, 2.0, 3.0, 4.0, 17.0, 18.0, 19.0, 20.0, 21.0, 40.0, 49.0, 54.0, 61.0, 80.0, 90.0,
    91.0, 91.1, 94.0,
];
/// Program stops, spindle, coolant.
const M_CODES: [f64; 10] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 7.0, 8.0, 9.0, 30.0];

/// Remove comments and whitespace: what GRBL's line buffer will hold.
pub fn strip(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut depth = 0;
    for c in line.chars() {
        match c {
            '(' => depth += 1,
            ')' if depth > 0 => depth -= 1,
            ';' if depth == 0 => break,
            c if depth == 0 && !c.is_whitespace() => out.push(c.to_ascii_uppercase()),
            _ => {}
        }
    }
    out
}

/// Parse one line (`number` only names it in errors).
pub fn parse_line(text: &str, number: usize) -> Result<Line> {
    let mut words = Vec::new();
    let mut comments = Vec::new();
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b'(' {
            let Some(end) = b[i..].iter().position(|&d| d == b')') else {
                bail!("line {number}: comment '(' is not closed");
            };
            comments.push(text[i + 1..i + end].trim().to_string());
            i += end + 1;
            continue;
        }
        if c == b';' {
            comments.push(text[i + 1..].trim().to_string());
            break;
        }
        if c.is_ascii_whitespace() || (c == b'%' && words.is_empty()) {
            i += 1;
            continue;
        }
        let letter = c.to_ascii_uppercase() as char;
        if !letter.is_ascii_alphabetic() {
            let bad = text[i..].chars().next().unwrap_or('?');
            bail!(
                "line {number}: unexpected character '{bad}' in '{}'",
                text.trim()
            );
        }
        i += 1;
        let start = i;
        let mut spaced = false;
        while i < b.len()
            && (b[i].is_ascii_digit() || matches!(b[i], b'.' | b'-' | b'+' | b' ' | b'\t'))
        {
            spaced |= b[i] == b' ' || b[i] == b'\t';
            i += 1;
        }
        let raw = &text[start..i];
        let num: std::borrow::Cow<str> = if spaced {
            raw.split_whitespace().collect::<String>().into()
        } else {
            raw.into()
        };
        let value: f64 = match num.parse() {
            Ok(v) if f64::is_finite(v) => v,
            _ => bail!(
                "line {number}: word '{letter}' has no valid number in '{}'",
                text.trim()
            ),
        };
        match letter {
            'G' if !G_CODES.contains(&value) => bail!("line {number}: unsupported command G{num}"),
            'M' if !M_CODES.contains(&value) => bail!("line {number}: unsupported command M{num}"),
            'G' | 'M' | 'X' | 'Y' | 'Z' | 'I' | 'J' | 'K' | 'R' | 'F' | 'S' | 'P' | 'N' | 'T' => {}
            _ => bail!("line {number}: unsupported word '{letter}{num}'"),
        }
        words.push((letter, value));
    }
    Ok(Line {
        number,
        words,
        comments,
    })
}

/// Parse a whole program; the first bad line is the error.
pub fn parse(text: &str) -> Result<Vec<Line>> {
    text.lines()
        .enumerate()
        .map(|(k, l)| parse_line(l, k + 1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_comments_case_and_spacing() {
        let l = parse_line("n10 g1x1.5 Y -2 (cut) z-0.25 F 600 ; tail", 3).unwrap();
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
        assert!(parse("G1 X1\nG1 Q5\n").unwrap_err().0.contains("line 2"));
        assert!(parse("G1 X1\n\nG38.2 Z-5\n")
            .unwrap_err()
            .0
            .contains("line 3"));
        assert!(parse("G1 X(oops\n").unwrap_err().0.contains("line 1"));
        assert!(parse("G1 X--1\n").unwrap_err().0.contains("line 1"));
        assert!(parse("M6\n").unwrap_err().0.contains("M6"));
    }
}
