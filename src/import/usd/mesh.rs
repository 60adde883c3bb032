//! A `UsdGeomMesh`'s face list onto triangles: polygons as fans, per-vertex or
//! face-varying attributes, and the points of one sample. Pure functions over arrays
//! (no stage), so the rules are tested here on their own.

use glam::{Vec2, Vec3};

use crate::scene::Topology;

/// How a primvar's values map onto the mesh (`interpolation` metadata).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Interp {
    /// One value per point (`vertex`, `varying`).
    Point,
    /// One value per face-vertex (`faceVarying`).
    Corner,
    /// `constant` or `uniform`: not read.
    Other,
}

impl Interp {
    pub(super) fn from_token(token: Option<&str>, default: Interp) -> Interp {
        match token {
            None => default,
            Some("vertex" | "varying") => Interp::Point,
            Some("faceVarying") => Interp::Corner,
            Some(_) => Interp::Other,
        }
    }
}

/// A primvar as read: values, optional `:indices`, how they map.
#[derive(Clone, Debug, Default)]
pub(super) struct Primvar<T> {
    pub values: Vec<T>,
    pub indices: Option<Vec<i32>>,
    pub interp: Option<Interp>,
}

/// Why a face list cannot be triangulated: the attribute at fault and what is wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct FaceError {
    pub attribute: &'static str,
    pub reason: String,
}

fn err(attribute: &'static str, reason: String) -> FaceError {
    FaceError { attribute, reason }
}

/// The triangles and per-vertex attributes of a face list over `points` points.
/// Polygons become fans around their first vertex (faces of fewer than three vertices
/// are dropped and counted); `left_handed` reverses the winding. Vertices are the
/// points themselves, or the face-vertices (each showing its point) when an attribute
/// is face-varying. Also returns the per-vertex normals when `normals` maps.
pub(super) fn triangulate(
    counts: &[i32],
    indices: &[i32],
    points: usize,
    left_handed: bool,
    st: Option<&Primvar<Vec2>>,
    normals: Option<&Primvar<Vec3>>,
) -> Result<(Topology, Option<Vec<Vec3>>, usize), FaceError> {
    let total: i64 = counts.iter().map(|&c| i64::from(c.max(0))).sum();
    if counts.iter().any(|&c| c < 0) {
        return Err(err("faceVertexCounts", "a negative count".into()));
    }
    if total != indices.len() as i64 {
        return Err(err(
            "faceVertexIndices",
            format!(
                "{} indices, but faceVertexCounts add up to {total}",
                indices.len()
            ),
        ));
    }
    if let Some((i, &bad)) = indices
        .iter()
        .enumerate()
        .find(|(_, &p)| p < 0 || p as usize >= points)
    {
        return Err(err(
            "faceVertexIndices",
            format!("[{i}] = {bad} is out of range for {points} points"),
        ));
    }
    let corners = st.is_some_and(|p| p.interp == Some(Interp::Corner))
        || normals.is_some_and(|p| p.interp == Some(Interp::Corner));
    let mut triangles = Vec::with_capacity(indices.len());
    let mut dropped = 0;
    let mut start = 0usize;
    for &c in counts {
        let c = c as usize;
        if c < 3 {
            dropped += 1;
            start += c;
            continue;
        }
        // A vertex is the face-vertex itself when splitting, else its point.
        let v = |k: usize| -> u32 {
            if corners {
                (start + k) as u32
            } else {
                indices[start + k] as u32
            }
        };
        for k in 1..c - 1 {
            triangles.push(if left_handed {
                [v(0), v(k + 1), v(k)]
            } else {
                [v(0), v(k), v(k + 1)]
            });
        }
        start += c;
    }
    let vertex_point = corners.then(|| indices.iter().map(|&p| p as u32).collect::<Vec<_>>());
    let nv = if corners { indices.len() } else { points };
    let uvs = match st {
        Some(pv) => Some(expand(pv, "primvars:st", indices, points, nv, corners)?),
        None => None,
    };
    let normals = match normals {
        Some(pv) => Some(expand(pv, "normals", indices, points, nv, corners)?),
        None => None,
    };
    Ok((
        Topology {
            triangles,
            vertex_point,
            uvs,
        },
        normals,
        dropped,
    ))
}

/// A primvar's value per vertex (`nv` of them; face-vertices when `corners`).
fn expand<T: Copy>(
    pv: &Primvar<T>,
    attribute: &'static str,
    face_indices: &[i32],
    points: usize,
    nv: usize,
    corners: bool,
) -> Result<Vec<T>, FaceError> {
    let interp = pv.interp.unwrap_or(Interp::Point);
    // The element count the interpolation asks for, before `:indices`.
    let elements = match interp {
        Interp::Point => points,
        Interp::Corner => face_indices.len(),
        Interp::Other => return Err(err(attribute, "constant or uniform: not read".into())),
    };
    let value = |e: usize| -> Result<T, FaceError> {
        let i = match &pv.indices {
            Some(ix) => {
                let Some(&j) = ix.get(e) else {
                    return Err(err(
                        attribute,
                        format!("{} indices for {elements} elements", ix.len()),
                    ));
                };
                j
            }
            None => e as i32,
        };
        usize::try_from(i)
            .ok()
            .and_then(|i| pv.values.get(i))
            .copied()
            .ok_or_else(|| {
                err(
                    attribute,
                    format!(
                        "element {e} names value {i} of {} ({elements} needed)",
                        pv.values.len()
                    ),
                )
            })
    };
    let mut out = Vec::with_capacity(nv);
    match (interp, corners) {
        (Interp::Point, false) => {
            for p in 0..points {
                out.push(value(p)?);
            }
        }
        (Interp::Point, true) => {
            for &p in face_indices {
                out.push(value(p as usize)?);
            }
        }
        (Interp::Corner, _) => {
            for e in 0..face_indices.len() {
                out.push(value(e)?);
            }
        }
        (Interp::Other, _) => unreachable!("returned above"),
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fans_and_winding() {
        // A quad and a triangle over 5 points; a two-vertex face dropped.
        let (t, _, dropped) = triangulate(
            &[4, 3, 2],
            &[0, 1, 2, 3, 1, 4, 2, 0, 1],
            5,
            false,
            None,
            None,
        )
        .unwrap();
        assert_eq!(t.triangles, [[0, 1, 2], [0, 2, 3], [1, 4, 2]]);
        assert!(t.vertex_point.is_none());
        assert_eq!(dropped, 1);
        let (t, _, _) = triangulate(&[4], &[0, 1, 2, 3], 4, true, None, None).unwrap();
        assert_eq!(t.triangles, [[0, 2, 1], [0, 3, 2]]);
    }

    #[test]
    fn face_varying_splits_vertices() {
        let st = Primvar {
            values: vec![Vec2::ZERO, Vec2::X, Vec2::ONE],
            indices: Some(vec![0, 1, 2, 2, 1, 0]),
            interp: Some(Interp::Corner),
        };
        let (t, _, _) =
            triangulate(&[3, 3], &[0, 1, 2, 2, 1, 3], 4, false, Some(&st), None).unwrap();
        assert_eq!(t.triangles, [[0, 1, 2], [3, 4, 5]]);
        assert_eq!(t.vertex_point.as_deref(), Some(&[0, 1, 2, 2, 1, 3][..]));
        let uv = t.uvs.unwrap();
        assert_eq!(uv[3], Vec2::ONE);
        assert_eq!(uv[5], Vec2::ZERO);
    }

    #[test]
    fn bad_indices_name_the_attribute() {
        let e = triangulate(&[3], &[0, 1, 7], 3, false, None, None).unwrap_err();
        assert_eq!(e.attribute, "faceVertexIndices");
        assert!(e.reason.contains("[2] = 7"), "{}", e.reason);
        let e = triangulate(&[4], &[0, 1, 2], 3, false, None, None).unwrap_err();
        assert!(e.reason.contains("add up to 4"), "{}", e.reason);
        let st = Primvar {
            values: vec![Vec2::ZERO],
            indices: None,
            interp: Some(Interp::Point),
        };
        let e = triangulate(&[3], &[0, 1, 2], 3, false, Some(&st), None).unwrap_err();
        assert_eq!(e.attribute, "primvars:st");
    }
}
