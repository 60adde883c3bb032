//! Tokens: whitespace-separated words with line numbers (`#` and `%` start comments to
//! the end of the line; `{` and `}` are tokens of their own), and the typed readers of one
//! file's statements (numbers, vectors, counts), whose errors name the file and line.

use std::path::Path;

use glam::{DVec3, Vec3};

use super::{ImportError, MAX_COUNT};

/// Tokens of one file, with line numbers.
pub(super) struct Lexer<'a> {
    src: &'a [u8],
    pos: usize,
    line: u32,
}

impl<'a> Lexer<'a> {
    pub(super) fn new(src: &'a [u8]) -> Self {
        Lexer {
            src,
            pos: 0,
            line: 1,
        }
    }

    /// The next token and its line (raw bytes).
    pub(super) fn next(&mut self) -> Option<(&'a [u8], u32)> {
        let s = self.src;
        loop {
            let c = *s.get(self.pos)?;
            match c {
                b'\n' => {
                    self.line += 1;
                    self.pos += 1;
                }
                b'#' | b'%' => {
                    while self.pos < s.len() && s[self.pos] != b'\n' {
                        self.pos += 1;
                    }
                }
                c if c.is_ascii_whitespace() => self.pos += 1,
                b'{' | b'}' => {
                    self.pos += 1;
                    return Some((&s[self.pos - 1..self.pos], self.line));
                }
                _ => break,
            }
        }
        let start = self.pos;
        while let Some(&c) = s.get(self.pos) {
            if c.is_ascii_whitespace() || matches!(c, b'#' | b'%' | b'{' | b'}') {
                break;
            }
            self.pos += 1;
        }
        Some((&s[start..self.pos], self.line))
    }

    pub(super) fn peek(&mut self) -> Option<(&'a [u8], u32)> {
        let (pos, line) = (self.pos, self.line);
        let t = self.next();
        self.pos = pos;
        self.line = line;
        t
    }
}

/// One file being read: its tokens and its name (for errors).
pub(super) struct Src<'a> {
    pub(super) lex: Lexer<'a>,
    pub(super) path: &'a Path,
    /// Line of the last token read (where "unexpected end" is reported).
    pub(super) line: u32,
}

impl<'a> Src<'a> {
    pub(super) fn err(&self, line: u32, message: impl Into<String>) -> ImportError {
        ImportError::Syntax {
            path: self.path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    pub(super) fn token(&mut self, what: &str) -> Result<(&'a str, u32), ImportError> {
        match self.lex.next() {
            None => Err(self.err(
                self.line,
                format!("unexpected end of file: expected {what}"),
            )),
            Some((raw, line)) => {
                self.line = line;
                let s = std::str::from_utf8(raw).map_err(|_| {
                    self.err(line, format!("expected {what}, found non-UTF-8 text"))
                })?;
                Ok((s, line))
            }
        }
    }

    pub(super) fn num(&mut self, what: &str) -> Result<f64, ImportError> {
        let (tok, line) = self.token(what)?;
        match tok.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(line, format!("expected a number ({what}), found {tok:?}"))),
        }
    }

    pub(super) fn f(&mut self, what: &str) -> Result<f32, ImportError> {
        let v = self.num(what)?;
        let f = v as f32;
        if f.is_finite() {
            Ok(f)
        } else {
            Err(self.err(self.line, format!("{what}: {v} is out of range")))
        }
    }

    pub(super) fn vec3(&mut self, what: &str) -> Result<Vec3, ImportError> {
        Ok(Vec3::new(self.f(what)?, self.f(what)?, self.f(what)?))
    }

    pub(super) fn dvec3(&mut self, what: &str) -> Result<DVec3, ImportError> {
        Ok(DVec3::new(
            self.num(what)?,
            self.num(what)?,
            self.num(what)?,
        ))
    }

    pub(super) fn count(&mut self, what: &str) -> Result<usize, ImportError> {
        let (tok, line) = self.token(what)?;
        match tok.parse::<u64>() {
            Ok(n) if n <= MAX_COUNT => Ok(n as usize),
            Ok(n) => Err(self.err(line, format!("{what}: {n} is too large"))),
            Err(_) => Err(self.err(line, format!("expected a count ({what}), found {tok:?}"))),
        }
    }

    pub(super) fn int(&mut self, what: &str) -> Result<i64, ImportError> {
        let (tok, line) = self.token(what)?;
        tok.parse::<i64>()
            .map_err(|_| self.err(line, format!("expected an integer ({what}), found {tok:?}")))
    }

    pub(super) fn expect(&mut self, want: &str, context: &str) -> Result<(), ImportError> {
        let (tok, line) = self.token(want)?;
        if tok == want {
            Ok(())
        } else {
            Err(self.err(
                line,
                format!("expected {want:?} after {context}, found {tok:?}"),
            ))
        }
    }

    /// Whether the next token is a number (without consuming it).
    pub(super) fn next_is_number(&mut self) -> bool {
        self.lex.peek().is_some_and(|(raw, _)| {
            std::str::from_utf8(raw).is_ok_and(|s| s.parse::<f64>().is_ok())
        })
    }

    pub(super) fn peek_str(&mut self) -> Option<&'a str> {
        self.lex
            .peek()
            .and_then(|(raw, _)| std::str::from_utf8(raw).ok())
    }
}
