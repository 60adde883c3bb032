//! Parsers of the command-line spellings of render options (`A..B`, `WxH`, `I/N`,
//! `X,Y,Z`, `depth,normal`), shared by the `render` and `demo` commands. Each bad value is
//! one error line naming the flag and the value. The types they produce stay in the
//! library (`subfield::render`); only the string parsing lives in the CLI.

use glam::Vec3;
use subfield::render::{
    Aovs, ExrCompression, FrameSet, FrameSpan, Shard, TraceDevice, MAX_FRAMES, MAX_SIDE,
};

fn bad(flag: &str, value: &str, why: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{flag} {value:?}: {why}")
}

/// A comma list of `N`, `A..B` (integers, `A < B`, B exclusive) and `A..B:S` (every
/// `S`-th frame from `A`), at most [`MAX_FRAMES`] frames in all. Each bad piece is named.
pub fn parse_frames(s: &str) -> anyhow::Result<FrameSet> {
    let num = |piece: &str, x: &str| {
        x.trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| n < u32::MAX)
            .ok_or_else(|| {
                bad(
                    "--frames",
                    s,
                    format!("{piece:?}: {:?} is not a frame number", x.trim()),
                )
            })
    };
    let mut spans = Vec::new();
    for piece in s.split(',') {
        let p = piece.trim();
        if p.is_empty() {
            return Err(bad(
                "--frames",
                s,
                "an empty piece; expected N, A..B or A..B:S, separated by commas",
            ));
        }
        let span = match p.split_once("..") {
            None => {
                let n = num(p, p)?;
                FrameSpan {
                    start: n,
                    end: n + 1,
                    step: 1,
                }
            }
            Some((a, rest)) => {
                let (b, step) = match rest.split_once(':') {
                    Some((b, st)) => match st.trim().parse::<u32>() {
                        Ok(k) if k >= 1 => (b, k),
                        _ => {
                            return Err(bad(
                                "--frames",
                                s,
                                format!(
                                    "{p:?}: the step {:?} is not a whole number >= 1",
                                    st.trim()
                                ),
                            ))
                        }
                    },
                    None => (rest, 1),
                };
                let (start, end) = (num(p, a)?, num(p, b)?);
                if end <= start {
                    return Err(bad(
                        "--frames",
                        s,
                        format!("{p:?}: the range is empty (the end is exclusive and must be above the start)"),
                    ));
                }
                FrameSpan { start, end, step }
            }
        };
        spans.push(span);
    }
    let set = FrameSet::new(spans);
    let n = set.count();
    if n > MAX_FRAMES {
        return Err(bad(
            "--frames",
            s,
            format!("{n} frames, more than the {MAX_FRAMES} a render takes (a typo?)"),
        ));
    }
    Ok(set)
}

/// `WxH`, both in `1..=32768`.
/// `--device cpu|gpu|auto`.
pub fn parse_device(s: &str) -> Result<TraceDevice, String> {
    match s {
        "cpu" => Ok(TraceDevice::Cpu),
        "gpu" => Ok(TraceDevice::Gpu),
        "auto" => Ok(TraceDevice::Auto),
        _ => Err(format!("{s:?}: expected cpu, gpu or auto")),
    }
}

pub fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| bad("--size", s, "expected WxH, e.g. 640x480"))?;
    let side = |x: &str| match x.trim().parse::<u32>() {
        Ok(v) if (1..=MAX_SIDE).contains(&v) => Ok(v),
        _ => Err(bad(
            "--size",
            s,
            format!("{x:?} is not a side length in 1..={MAX_SIDE}"),
        )),
    };
    Ok((side(w)?, side(h)?))
}

/// `I/N` with `N >= 1` and `I < N`.
pub fn parse_shard(s: &str) -> anyhow::Result<Shard> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| bad("--shard", s, "expected I/N, e.g. 0/4"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<u32>()
            .map_err(|_| bad("--shard", s, format!("{x:?} is not a whole number")))
    };
    let (index, count) = (num(i)?, num(n)?);
    if count == 0 || index >= count {
        return Err(bad("--shard", s, "needs N >= 1 and 0 <= I < N"));
    }
    Ok(Shard { index, count })
}

/// `X,Y,Z` (finite numbers).
pub fn parse_vec3(flag: &str, s: &str) -> anyhow::Result<Vec3> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(bad(flag, s, "expected X,Y,Z"));
    }
    let mut v = [0.0f32; 3];
    for (dst, p) in v.iter_mut().zip(&parts) {
        *dst = match p.trim().parse::<f32>() {
            Ok(x) if x.is_finite() => x,
            _ => return Err(bad(flag, s, format!("{p:?} is not a finite number"))),
        };
    }
    Ok(Vec3::from_array(v))
}

/// `--compression zip|piz|none`; `dwaa` (which DESIGN.md §4 names) is refused in one
/// line: the `exr` crate reads DWAA but cannot write it.
pub fn parse_compression(s: &str) -> Result<ExrCompression, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "zip" => Ok(ExrCompression::Zip),
        "piz" => Ok(ExrCompression::Piz),
        "none" => Ok(ExrCompression::None),
        "dwaa" | "dwab" => Err(format!(
            "{s}: not available: the exr crate this build uses reads DWA but cannot write it; \
             use zip (the default) or piz"
        )),
        _ => Err(format!("{s}: not one of zip, piz, none")),
    }
}

/// `depth,normal,albedo,position,motion,cryptomatte,diffuse,specular,transmission,emission`
/// in any order and subset.
pub fn parse_aovs(s: &str) -> anyhow::Result<Aovs> {
    let mut a = Aovs::default();
    for name in s.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        match name {
            "depth" | "Z" | "z" => a.depth = true,
            "normal" | "N" => a.normal = true,
            "albedo" => a.albedo = true,
            "position" | "P" => a.position = true,
            "motion" => a.motion = true,
            "cryptomatte" | "crypto" => a.cryptomatte = true,
            "diffuse" => a.diffuse = true,
            "specular" | "glossy" => a.specular = true,
            "transmission" => a.transmission = true,
            "emission" => a.emission = true,
            other => {
                return Err(bad(
                    "--aov",
                    s,
                    format!(
                        "unknown AOV {other:?} (known: depth, normal, albedo, position, \
                         motion, cryptomatte, diffuse, specular, transmission, emission)"
                    ),
                ))
            }
        }
    }
    Ok(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_parse_and_reject() {
        let frames = |s: &str| parse_frames(s).unwrap().frames().unwrap();
        assert_eq!(frames("0..10"), (0..10).collect::<Vec<u32>>());
        assert_eq!(frames(" 3 .. 4"), [3]);
        assert_eq!(frames("5"), [5]);
        assert_eq!(frames("0..800:100"), [0, 100, 200, 300, 400, 500, 600, 700]);
        assert_eq!(frames("0..7:3"), [0, 3, 6]);
        let list: Vec<u32> = (0..10).chain([47]).chain(50..60).collect();
        assert_eq!(frames("0..10,47,50..60"), list);
        // Overlaps and order do not matter: sorted, each frame once.
        assert_eq!(frames("8,2..5,3,4..6"), [2, 3, 4, 5, 8]);
        // The spelling reads back as the same frames.
        for spec in ["0..10,47,50..60", "0..800:100", "7", "3..9:2,1"] {
            let set = parse_frames(spec).unwrap();
            assert_eq!(set.to_string(), spec);
            let again = FrameSet::from_sorted(&set.frames().unwrap());
            assert_eq!(again.frames().unwrap(), set.frames().unwrap(), "{spec}");
        }
        assert_eq!(
            FrameSet::from_sorted(&[0, 1, 2, 5, 10, 20, 30, 31]).to_string(),
            "0..3,5,10..31:10,31"
        );
        for (s, piece) in [
            ("5..2", "\"5..2\""),
            ("2..2", "\"2..2\""),
            ("a..3", "\"a\""),
            ("-1..4", "\"-1\""),
            ("1..b", "\"b\""),
            ("0..10,x", "\"x\""),
            ("0..10,,12", "empty piece"),
            ("0..10:0", "step"),
            ("0..10:-2", "step"),
            ("4294967295", "not a frame number"),
            ("0..4000000000", "10000000"),
            ("0..6000000,0..6000000", "10000000"),
        ] {
            let e = parse_frames(s).unwrap_err().to_string();
            assert!(e.starts_with("--frames") && e.contains(piece), "{s}: {e}");
        }
    }

    #[test]
    fn size_shard_vec_aov() {
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
        assert_eq!(parse_size("1X1").unwrap(), (1, 1));
        for s in ["0x10", "10x", "x", "640*480", "99999x2", "-3x4"] {
            assert!(parse_size(s).is_err(), "{s}");
        }
        assert_eq!(parse_shard("1/2").unwrap(), Shard { index: 1, count: 2 });
        for s in ["2/2", "0/0", "1", "a/b", "-1/2"] {
            assert!(parse_shard(s).is_err(), "{s}");
        }
        assert_eq!(
            parse_vec3("--up", "0, 1,0").unwrap(),
            Vec3::new(0.0, 1.0, 0.0)
        );
        for s in ["1,2", "1,2,3,4", "1,nan,2", "1,inf,2", "a,b,c"] {
            assert!(parse_vec3("--up", s).is_err(), "{s}");
        }
        let a = parse_aovs("albedo,depth").unwrap();
        assert!(a.depth && a.albedo && !a.normal);
        let a = parse_aovs("position,motion,cryptomatte").unwrap();
        assert!(a.position && a.motion && a.cryptomatte && !a.depth);
        assert!(parse_aovs("depth,colour").is_err());
        let a = parse_aovs("diffuse,specular,transmission,emission").unwrap();
        assert_eq!(a.light_paths(), [true; 4]);
        assert_eq!(a.names(), "diffuse,specular,transmission,emission");
        let a = parse_aovs("emission").unwrap();
        assert_eq!(a.light_paths(), [false, false, false, true]);
        assert_eq!(parse_compression("piz"), Ok(ExrCompression::Piz));
        assert_eq!(parse_compression("zip"), Ok(ExrCompression::Zip));
        assert_eq!(parse_compression("none"), Ok(ExrCompression::None));
        assert!(parse_compression("dwaa")
            .unwrap_err()
            .contains("cannot write"));
        assert!(parse_compression("b44").is_err());
    }
}
