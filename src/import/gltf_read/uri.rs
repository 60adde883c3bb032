//! Buffers and URIs: the GLB binary chunk, `data:` URIs (base64 or percent-encoded) and
//! files beside the scene, refusing any URI that leaves the scene's folder (the policy of
//! `import::folder`).

use std::borrow::Cow;
use std::path::Path;

use super::{json, ImportError, Importer};

impl<'a> Importer<'a> {
    /// Every buffer's bytes, `None` for a buffer that has none to load: a meshopt
    /// `fallback` buffer, or one without a URI that is not the GLB's binary chunk. Only
    /// a buffer view that is read needs its buffer's bytes ([`Self::buffer_bytes`]), so
    /// a buffer nothing reads may have none, as the specification allows.
    pub(super) fn load_buffers(
        &self,
        bin: Option<&'a [u8]>,
    ) -> Result<Vec<Option<Cow<'a, [u8]>>>, ImportError> {
        let mut out = Vec::new();
        for (i, buffer) in self.root.buffers.iter().enumerate() {
            let err = |reason: String| ImportError::Buffer {
                path: self.path.to_path_buf(),
                buffer: i,
                reason,
            };
            // Only compressed views read a meshopt fallback buffer, and they read the
            // compressed buffer instead: it need not be loaded (it may hold no data).
            if is_fallback(buffer) {
                out.push(None);
                continue;
            }
            let data: Cow<'a, [u8]> = match (&buffer.uri, i, bin) {
                (Some(uri), _, _) => Cow::Owned(self.load_uri(uri, &format!("buffers[{i}]"))?),
                (None, 0, Some(b)) => Cow::Borrowed(b),
                (None, _, _) => {
                    out.push(None);
                    continue;
                }
            };
            let length = buffer.byte_length.unwrap_or(0);
            if data.len() < length {
                return Err(err(format!(
                    "holds {} bytes but byteLength is {length}",
                    data.len(),
                )));
            }
            out.push(Some(match data {
                Cow::Borrowed(b) => Cow::Borrowed(&b[..length]),
                Cow::Owned(mut v) => {
                    v.truncate(length);
                    Cow::Owned(v)
                }
            }));
        }
        Ok(out)
    }

    /// The bytes of `buffers[b]`, or why it has none: the reason names the buffer, the
    /// caller adds the buffer view and what read it.
    pub(super) fn buffer_bytes(&self, b: usize) -> Result<&[u8], String> {
        match (self.buffers.get(b), self.root.buffers.get(b)) {
            (Some(Some(bytes)), _) => Ok(bytes),
            (Some(None), Some(buffer)) if is_fallback(buffer) => Err(format!(
                "buffers[{b}] is a meshopt fallback buffer, which only compressed views may \
                 name (it is not loaded)"
            )),
            (Some(None), _) if b == 0 => Err(
                "buffers[0] has no data: it has no URI and the file has no GLB binary chunk"
                    .to_string(),
            ),
            (Some(None), _) => Err(format!(
                "buffers[{b}] has no data: it has no URI, and only buffers[0] may be a .glb's \
                 binary chunk"
            )),
            (None, _) => Err(format!("buffers[{b}] does not exist")),
        }
    }

    /// Reads a `data:` URI or a file relative to the scene's folder. A URI that leaves the
    /// folder (absolute, `..` above it, another scheme) is refused.
    pub(super) fn load_uri(&self, uri: &str, what: &str) -> Result<Vec<u8>, ImportError> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let bad = |reason: String| ImportError::BadUri {
                path: self.path.to_path_buf(),
                what: what.to_string(),
                reason,
            };
            let (meta, payload) = rest
                .split_once(',')
                .ok_or_else(|| bad("data URI without a comma".into()))?;
            return if meta.ends_with(";base64") {
                decode_base64(payload).map_err(|r| bad(format!("bad base64 in data URI: {r}")))
            } else {
                Ok(percent_decode(payload))
            };
        }
        let refuse = || ImportError::UriOutsideFolder {
            path: self.path.to_path_buf(),
            what: what.to_string(),
            uri: uri.to_string(),
        };
        // A scheme ("http:", "file:", "C:") is never a relative reference.
        if let Some(colon) = uri.find(':') {
            if !uri[..colon].contains('/') {
                return Err(refuse());
            }
        }
        let decoded = String::from_utf8(percent_decode(uri)).map_err(|_| refuse())?;
        // The policy every reference to a file beside the scene follows (import::folder).
        let resolved = crate::import::folder::resolve_inside(self.folder, Path::new(&decoded))
            .map_err(|_| refuse())?;
        crate::import::read::read_whole(&resolved).map_err(|source| ImportError::MissingFile {
            path: self.path.to_path_buf(),
            what: what.to_string(),
            uri: uri.to_string(),
            resolved,
            source,
        })
    }
}

/// A buffer that `EXT_meshopt_compression` / `KHR_meshopt_compression` marks `fallback`.
fn is_fallback(buffer: &json::Buffer) -> bool {
    buffer.extensions.as_ref().is_some_and(|e| {
        e.ext_meshopt.as_ref().is_some_and(|m| m.fallback)
            || e.khr_meshopt.as_ref().is_some_and(|m| m.fallback)
    })
}

/// `%XX` escapes decoded; malformed escapes kept as they are.
pub(super) fn percent_decode(s: &str) -> Vec<u8> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = |c: u8| (c as char).to_digit(16);
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    out
}

/// Standard or URL-safe base64, padding optional.
pub(crate) fn decode_base64(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3 + 3);
    let mut acc: u32 = 0;
    let mut bits = 0u32;
    for (i, c) in s.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            _ => return Err(format!("invalid character {:?} at {i}", c as char)),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_known_vectors() {
        assert_eq!(decode_base64("").unwrap(), b"");
        assert_eq!(decode_base64("Zg==").unwrap(), b"f");
        assert_eq!(decode_base64("Zm8=").unwrap(), b"fo");
        assert_eq!(decode_base64("Zm9v").unwrap(), b"foo");
        assert_eq!(decode_base64("Zm9vYmFy").unwrap(), b"foobar");
        assert_eq!(decode_base64("Zm9vYg").unwrap(), b"foob");
        assert!(decode_base64("Zm9v!").is_err());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), b"a b.bin");
        assert_eq!(percent_decode("100%"), b"100%");
        assert_eq!(percent_decode("%4"), b"%4");
        assert_eq!(percent_decode("%zz"), b"%zz");
    }
}
