//! The scene paths a layer holds, checked before the USD reader sees them. `openusd`
//! (0.6) parses a malformed path such as `<}>` or `<r }>` (a relationship's target, a
//! connection) without complaint, and composing it then recurses without end: the
//! stack overflows after milliseconds, or after minutes where the path grows at each
//! step (both found by the fuzz target `usd_import`). A path is refused here, naming
//! the layer's line, if it holds what no scene path has: white space or a control
//! character, a character outside names and the path's punctuation, a `}` without its
//! `{`, a variant selection that is not `{set=selection}`, an unbalanced `[`.
//!
//! The check is deliberately loose where USD's grammar is rich (names may be any
//! Unicode letters and digits; property names have `:` namespaces; target paths nest in
//! `[...]`): it refuses only what cannot be a path, so no valid file is refused.

/// Why `path` (a path literal's text, without `<` `>`) cannot be a scene path, if so.
pub(super) fn malformed(path: &str) -> Option<&'static str> {
    let mut chars = path.chars().peekable();
    let mut brackets = 0usize;
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() || c.is_control() => {
                return Some("white space or a control character")
            }
            c if c.is_alphanumeric() || matches!(c, '_' | '/' | '.' | ':' | '-') => {}
            '[' => brackets += 1,
            ']' => {
                brackets = match brackets.checked_sub(1) {
                    Some(b) => b,
                    None => return Some("a ']' without its '['"),
                }
            }
            '{' => {
                // `{set=selection}`: a name, '=', a selection (maybe empty).
                let mut set = 0;
                let mut equals = false;
                loop {
                    match chars.next() {
                        None => return Some("a '{' without its '}'"),
                        Some('}') if equals => break,
                        Some('=') if !equals && set > 0 => equals = true,
                        Some(c)
                            if c.is_alphanumeric() || matches!(c, '_' | '|' | '-' | '.' | ':') =>
                        {
                            if !equals {
                                set += 1;
                            }
                        }
                        Some(_) => return Some("a variant selection that is not {set=selection}"),
                    }
                }
            }
            '}' => return Some("a '}' without its '{'"),
            _ => return Some("a character that no scene path has"),
        }
    }
    (brackets > 0).then_some("a '[' without its ']'")
}

/// Whether `name` can name a prim: a letter or `_`, then letters, digits or `_`.
fn prim_name(name: &str) -> bool {
    openusd::sdf::Path::is_valid_identifier(name)
}

/// The first malformed path literal (`<...>`) or prim name (`def Mesh "name"`) of a
/// `.usda` layer's text, with its line: the text is scanned as the format's lexer would,
/// past comments, strings (single, double, triple quoted) and asset paths (`@...@`,
/// `@@@...@@@`).
pub(super) fn check_usda(b: &[u8]) -> Result<(), String> {
    // The line of byte `at`, for an error.
    let line = |at: usize| 1 + memchr::memchr_iter(b'\n', &b[..at]).count();
    let text = |from: usize, to: usize| String::from_utf8_lossy(&b[from..to]);
    // Skips to just past `close` from `i`; a backslash escapes the next byte where
    // `escapes`.
    let skip = |i: &mut usize, close: &[u8], escapes: bool| {
        while *i < b.len() {
            if b[*i..].starts_with(close) {
                *i += close.len();
                return;
            }
            if escapes && b[*i] == b'\\' {
                *i += 1;
            }
            *i += 1;
        }
    };
    // The next `@` or `'` at or after a position, kept: those are rare, and a search for
    // them from every `"`, `<` or `#` would scan to the end of a long file each time.
    let mut other = 0;
    let mut next_other = |from: usize| -> usize {
        if other < from {
            other = memchr::memchr2(b'@', b'\'', &b[from..]).map_or(b.len(), |n| from + n);
        }
        other
    };
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'#' => {
                i = memchr::memchr(b'\n', &b[i..]).map_or(b.len(), |n| i + n);
            }
            q @ (b'"' | b'\'') => {
                let triple = [q, q, q];
                if b[i..].starts_with(&triple) {
                    i += 3;
                    skip(&mut i, &triple, true);
                } else {
                    let at = i;
                    let names_prim = after_specifier(&b[..i]);
                    let start = i + 1;
                    i += 1;
                    skip(&mut i, &[q], true);
                    let name = text(start, i.saturating_sub(1).max(start));
                    if names_prim && !prim_name(&name) {
                        return Err(format!(
                            "line {}: the prim name \"{}\" is not a name (a letter or '_', then \
                             letters, digits or '_')",
                            line(at),
                            shown(&name)
                        ));
                    }
                }
            }
            b'@' => {
                if b[i..].starts_with(b"@@@") {
                    i += 3;
                    skip(&mut i, b"@@@", false);
                } else {
                    i += 1;
                    skip(&mut i, b"@", false);
                }
            }
            b'<' => {
                let start = i + 1;
                let Some(len) = memchr::memchr(b'>', &b[start..]) else {
                    // Unclosed: the reader's parser says so.
                    return Ok(());
                };
                let path = text(start, start + len);
                if let Some(why) = malformed(&path) {
                    return Err(format!(
                        "line {}: the path <{}> is not a scene path ({why})",
                        line(i),
                        shown(&path)
                    ));
                }
                i = start + len + 1;
            }
            // Only those bytes start something to look at: the rest (numbers above all)
            // is passed over by `memchr`.
            _ => {
                let from = i + 1;
                let common =
                    memchr::memchr3(b'#', b'"', b'<', &b[from..]).map_or(b.len(), |n| from + n);
                i = common.min(next_other(from));
            }
        }
    }
    Ok(())
}

/// Whether the text before a string ends in `def`, `over` or `class`, maybe followed by
/// a type name (`def Mesh`): the string is then a prim's name. Read backwards over
/// white space and words (letters, digits, `_`, `:`).
fn after_specifier(before: &[u8]) -> bool {
    let word_char = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b':';
    let mut end = before.len();
    let word = |end: &mut usize| -> &[u8] {
        while *end > 0 && before[*end - 1].is_ascii_whitespace() {
            *end -= 1;
        }
        let stop = *end;
        while *end > 0 && word_char(before[*end - 1]) {
            *end -= 1;
        }
        &before[*end..stop]
    };
    let specifier = |w: &[u8]| matches!(w, b"def" | b"over" | b"class");
    let last = word(&mut end);
    if specifier(last) {
        return true;
    }
    if last.is_empty() || !prim_name(&String::from_utf8_lossy(last)) {
        return false;
    }
    specifier(word(&mut end))
}

/// The first malformed path of a `.usdc` layer (its PATHS section, as the USD reader
/// decodes it). A file the reader cannot open is left to the reader, which says why.
pub(super) fn check_usdc(bytes: &[u8]) -> Result<(), String> {
    let Ok(file) = openusd::usdc::CrateFile::open(std::io::Cursor::new(bytes)) else {
        return Ok(());
    };
    for p in &file.paths {
        if let Some(why) = malformed(p.as_str()) {
            return Err(format!(
                "the path <{}> is not a scene path ({why})",
                shown(p.as_str())
            ));
        }
    }
    Ok(())
}

/// A layer's bytes by their kind (text or crate file; anything else is the reader's).
pub(super) fn check_layer(bytes: &[u8]) -> Result<(), String> {
    if bytes.starts_with(openusd::usdc::MAGIC) {
        check_usdc(bytes)
    } else if bytes.starts_with(b"#usda") {
        check_usda(bytes)
    } else {
        Ok(())
    }
}

/// A path or name for an error line: at most 80 characters, control characters escaped
/// as the import's errors escape them.
pub(super) fn shown(path: &str) -> String {
    let cut: String = path.chars().take(80).collect();
    let mut s = crate::import::error::printable(&cut).into_owned();
    if path.chars().count() > 80 {
        s.push('…');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_of_valid_files_pass() {
        for p in [
            "",
            "/",
            "/World",
            "/World/Looks/Plain",
            "/World/Looks/Plain.outputs:surface",
            "/World/Surface/Tex.outputs:rgb",
            "../Sibling",
            "./Child",
            "Child/Grand",
            "/Set{shading=red}Mesh/Part",
            "/Set{shading=}Mesh",
            "/Set{lod=lod-1}{look=a|b}Mesh",
            "/A.rel[/B/C].attr",
            "/Wörld/Ωmega_1",
            "/World/Debris.velocities",
        ] {
            assert_eq!(malformed(p), None, "{p:?}");
        }
    }

    #[test]
    fn what_no_path_has_is_refused() {
        for (p, why) in [
            ("}", "'}' without"),
            ("r }", "white space"),
            ("}\n", "'}' without"),
            ("/World/Look   uniform token", "white space"),
            ("/A{v=x", "'{' without"),
            ("/A{=x}B", "not {set=selection}"),
            ("/A{vx}B", "not {set=selection}"),
            ("/A{v=x y}B", "not {set=selection}"),
            ("/A.rel[/B", "'[' without"),
            ("/A]", "']' without"),
            ("/A\"B", "no scene path"),
            ("/A@B", "no scene path"),
        ] {
            let got = malformed(p);
            assert!(got.is_some_and(|g| g.contains(why)), "{p:?}: {got:?}");
        }
    }

    #[test]
    fn the_text_is_scanned_past_comments_strings_and_assets() {
        let ok = "#usda 1.0\n(\n    doc = \"\"\"a <} > in a\ndocstring\"\"\"\n)\n# a <}> in a comment\n\
                  def \"W\" (references = @./a<}>.usda@</Asset>)\n{\n    string s = \"<}>\\\"<}>\"\n    \
                  string t = '<}>'\n    asset a = @@@x@y<}>@@@\n    rel r = </W/M{v=a}N.x>\n}\n";
        assert_eq!(check_usda(ok.as_bytes()), Ok(()));
        // Prim names: only after `def`, `over`, `class` (and a type name).
        let names =
            "#usda 1.0\ndef Xform \"Wörld_1\" (kind = \"a b\")\n{\n    over \"_x\" {}\n    \
                     class \"C\" {}\n    variantSet \"shading set\" = { \"red one\" {} }\n    \
                     string def = \"a b\"\n}\n";
        assert_eq!(check_usda(names.as_bytes()), Ok(()));
        let e = check_usda(b"#usda 1.0\ndef \"d\"\n{\n def \"\n}O}\" {}\n}\n").unwrap_err();
        assert!(e.starts_with("line 4: the prim name \"\\n}O}\""), "{e}");
        let e = check_usda(b"#usda 1.0\ndef Mesh \"1st\" {}\n").unwrap_err();
        assert!(e.starts_with("line 2: the prim name \"1st\""), "{e}");
        let bad = "#usda 1.0\ndef \"W\"\n{\n    rel material:binding = <r }>\n}\n";
        let e = check_usda(bad.as_bytes()).unwrap_err();
        assert!(e.starts_with("line 4: the path <r }>"), "{e}");
        // Lines counted past a multi-line string and path.
        let bad = "#usda 1.0\n\"\"\"\n\n\"\"\"\nrel a = </A>\nrel b = <\n}>\n";
        let e = check_usda(bad.as_bytes()).unwrap_err();
        assert!(e.starts_with("line 6: the path <\\n}>"), "{e}");
    }
}
