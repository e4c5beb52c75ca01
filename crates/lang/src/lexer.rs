//! Tokens of the rule language.

use crate::ast::Pos;

/// A token.
#[derive(Clone, Debug, PartialEq)]
pub enum Tok {
    /// An identifier or keyword.
    Ident(String),
    /// An integer literal.
    Int(i64),
    /// The literal `9223372036854775808` (2^63, one past the largest i64): only valid after
    /// a unary minus, where it is the smallest i64 (the parser checks).
    IntMinMagnitude,
    /// A real literal (has a `.` or an exponent).
    Real(f64),
    /// A string literal `"..."` (no escapes; it ends at the next `"` on its line).
    Str(String),
    /// Punctuation or operator: `{ } ( ) < > , : ; = - + * / % ! . _ == != <= >= && ||`.
    Punct(&'static str),
    /// End of input.
    Eof,
}

impl Tok {
    /// How the token reads in a message.
    pub fn describe(&self) -> String {
        match self {
            Tok::Ident(s) => format!("'{s}'"),
            Tok::Int(i) => format!("'{i}'"),
            Tok::IntMinMagnitude => "'9223372036854775808'".into(),
            Tok::Real(x) => format!("'{x}'"),
            Tok::Str(s) => format!("\"{s}\""),
            Tok::Punct(p) => format!("'{p}'"),
            Tok::Eof => "end of file".into(),
        }
    }
}

/// A lexing error.
#[derive(Clone, Debug, PartialEq)]
pub struct LexError {
    /// Where.
    pub pos: Pos,
    /// What.
    pub message: String,
}

const PUNCTS: [&str; 26] = [
    "==", "!=", "<=", ">=", "&&", "||", "{", "}", "(", ")", "<", ">", ",", ":", ";", "=", "-", "+",
    "*", "/", "%", "!", ".", "_", "[", "]",
];

/// Splits `src` into tokens with their positions; `#` starts a comment to the end of the line.
pub fn lex(src: &str) -> Result<Vec<(Tok, Pos)>, LexError> {
    // a byte-order mark (what some editors write first in a UTF-8 file) is not text: the
    // first character after it is at 1:1
    let src = src.strip_prefix('\u{feff}').unwrap_or(src);
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line, mut col) = (0usize, 1u32, 1u32);
    while i < chars.len() {
        let c = chars[i];
        let pos = Pos { line, col };
        if c == '\n' {
            i += 1;
            line += 1;
            col = 1;
            continue;
        }
        if c.is_whitespace() {
            i += 1;
            col += 1;
            continue;
        }
        if c == '#' {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
            continue;
        }
        if c.is_ascii_alphabetic()
            || (c == '_'
                && chars
                    .get(i + 1)
                    .is_some_and(|n| n.is_ascii_alphanumeric() || *n == '_'))
        {
            let start = i;
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '_') {
                i += 1;
            }
            let s: String = chars[start..i].iter().collect();
            col += (i - start) as u32;
            out.push((Tok::Ident(s), pos));
            continue;
        }
        if c.is_ascii_digit() {
            let start = i;
            while i < chars.len() && chars[i].is_ascii_digit() {
                i += 1;
            }
            let mut real = false;
            if i + 1 < chars.len() && chars[i] == '.' && chars[i + 1].is_ascii_digit() {
                real = true;
                i += 1;
                while i < chars.len() && chars[i].is_ascii_digit() {
                    i += 1;
                }
            }
            if i < chars.len() && (chars[i] == 'e' || chars[i] == 'E') {
                let mut j = i + 1;
                if j < chars.len() && (chars[j] == '+' || chars[j] == '-') {
                    j += 1;
                }
                if j < chars.len() && chars[j].is_ascii_digit() {
                    real = true;
                    i = j;
                    while i < chars.len() && chars[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let s: String = chars[start..i].iter().collect();
            col += (i - start) as u32;
            let tok = if real {
                let x: f64 = s.parse().map_err(|_| LexError {
                    pos,
                    message: format!("bad number '{s}'"),
                })?;
                // a literal past the largest f64 would read as infinity
                if !x.is_finite() {
                    return Err(LexError {
                        pos,
                        message: format!(
                            "number '{s}' is too large (the largest is about 1.8e308)"
                        ),
                    });
                }
                Tok::Real(x)
            } else {
                match s.parse() {
                    Ok(i) => Tok::Int(i),
                    // 2^63 after a minus: the smallest i64, if the minus is its sign (the
                    // parser tells); anywhere else no i64 holds it
                    Err(_)
                        if s.trim_start_matches('0') == "9223372036854775808"
                            && matches!(out.last(), Some((Tok::Punct("-"), _))) =>
                    {
                        Tok::IntMinMagnitude
                    }
                    Err(_) => {
                        return Err(LexError {
                            pos,
                            message: format!(
                                "integer '{s}' is too large (integers are i64: from -9223372036854775808 to 9223372036854775807)"
                            ),
                        })
                    }
                }
            };
            out.push((tok, pos));
            continue;
        }
        if c == '"' {
            let start = i + 1;
            let mut j = start;
            while j < chars.len() && chars[j] != '"' && chars[j] != '\n' {
                j += 1;
            }
            if j >= chars.len() || chars[j] != '"' {
                return Err(LexError {
                    pos,
                    message: "string not closed: a '\"' is missing before the end of the line"
                        .into(),
                });
            }
            let s: String = chars[start..j].iter().collect();
            col += (j + 1 - i) as u32;
            i = j + 1;
            out.push((Tok::Str(s), pos));
            continue;
        }
        let rest: String = chars[i..(i + 2).min(chars.len())].iter().collect();
        if let Some(p) = PUNCTS.iter().find(|p| rest.starts_with(**p)) {
            i += p.len();
            col += p.len() as u32;
            out.push((Tok::Punct(p), pos));
            continue;
        }
        return Err(LexError {
            pos,
            message: format!("unexpected character {c:?}"),
        });
    }
    out.push((Tok::Eof, Pos { line, col }));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lexes_arcs_orbits_and_numbers() {
        let t: Vec<Tok> = lex("a -2- b <0,_> 1.5e-3 2 x_1 # c\n>=")
            .unwrap()
            .into_iter()
            .map(|x| x.0)
            .collect();
        assert_eq!(
            t,
            vec![
                Tok::Ident("a".into()),
                Tok::Punct("-"),
                Tok::Int(2),
                Tok::Punct("-"),
                Tok::Ident("b".into()),
                Tok::Punct("<"),
                Tok::Int(0),
                Tok::Punct(","),
                Tok::Punct("_"),
                Tok::Punct(">"),
                Tok::Real(1.5e-3),
                Tok::Int(2),
                Tok::Ident("x_1".into()),
                Tok::Punct(">="),
                Tok::Eof
            ]
        );
    }

    #[test]
    fn a_real_past_the_largest_float_is_refused_not_read_as_infinity() {
        let e = lex("x > 1e999").unwrap_err();
        assert!(e.message.contains("'1e999' is too large"), "{}", e.message);
        assert_eq!(e.pos, Pos { line: 1, col: 5 });
        assert_eq!(lex("1.7e308").unwrap()[0].0, Tok::Real(1.7e308));
        // underflow is no error: the nearest float is 0 or a subnormal
        assert_eq!(lex("1e-999").unwrap()[0].0, Tok::Real(0.0));
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        let t = lex("\u{feff}dimension 3").unwrap();
        assert_eq!(
            t[0],
            (Tok::Ident("dimension".into()), Pos { line: 1, col: 1 })
        );
        // elsewhere it is a character the language does not have
        assert!(lex("dimension \u{feff}3").is_err());
    }

    #[test]
    fn positions_are_line_and_column() {
        let t = lex("a\n  bb $").unwrap_err();
        assert_eq!(t.pos, Pos { line: 2, col: 6 });
        let ok = lex("a\n  bb").unwrap();
        assert_eq!(ok[1].1, Pos { line: 2, col: 3 });
    }
}
