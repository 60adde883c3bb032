//! Emissive triangles as area lights. Each frame, every triangle whose material emits
//! becomes an [`Emitter`]; one is chosen per light sample with probability
//! proportional to its power (luminance of `emissive × strength` × area, twice that
//! when double-sided) from a cumulative table (a binary search, so a scene with many
//! emissive triangles costs `log n` a sample, not a loop over all), and a point on it
//! uniformly by area. Emission textures are applied at the chosen point, not in the
//! table. A single-sided material emits from its front face (the side its winding makes
//! the front, as glTF culls the back), a double-sided one from both.

use glam::{Vec2, Vec3};

use crate::scene::{Material, Scene, TriangleSoup};

/// One emissive triangle, world space.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub(super) struct Emitter {
    pub p0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    /// Unit normal of the front face (`e1 × e2`).
    pub normal: Vec3,
    pub area: f32,
    /// The hit number of the triangle (static first, then moving), as the tracer
    /// reports it.
    pub tri: u32,
    pub material: u32,
    pub two_sided: bool,
}

/// A point chosen on an emitter.
#[derive(Clone, Copy, Debug)]
pub(super) struct LightPoint {
    pub point: Vec3,
    /// Unit front normal of the emitter.
    pub normal: Vec3,
    pub two_sided: bool,
    /// Barycentrics `(u, v)` of the point (for the emission texture).
    pub bary: Vec2,
    pub tri: u32,
    pub material: u32,
    /// Probability density of the point, per unit area.
    pub pdf_area: f32,
}

/// The frame's emissive triangles and their power table.
#[derive(Clone, Debug, Default)]
pub(super) struct AreaLights {
    emitters: Vec<Emitter>,
    /// `cdf[i]`: share of the total power in emitters `0..=i` (the last is 1).
    cdf: Vec<f32>,
}

fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Power a unit area of `m` gives off, for the table (0: it does not emit).
fn material_power(m: &Material) -> f32 {
    let l = luminance(m.emissive * m.emissive_strength);
    let sides = if m.double_sided { 2.0 } else { 1.0 };
    if l.is_finite() && l > 0.0 {
        l * sides
    } else {
        0.0
    }
}

/// Whether triangles of `m` become area lights.
pub(super) fn emits(m: &Material) -> bool {
    material_power(m) > 0.0
}

impl AreaLights {
    /// Emitters of the static then the moving triangles (hit numbers in that order).
    pub fn new(scene: &Scene, static_soup: &TriangleSoup, dynamic_soup: &TriangleSoup) -> Self {
        // Power a unit area of each material gives off (0: it does not emit).
        let power: Vec<f32> = scene.materials.iter().map(material_power).collect();
        if power.iter().all(|&p| p == 0.0) {
            return AreaLights::default();
        }
        let mut emitters = Vec::new();
        let mut weights = Vec::new();
        let mut base = 0u32;
        for soup in [static_soup, dynamic_soup] {
            for (i, (p, &m)) in soup.positions.iter().zip(&soup.material).enumerate() {
                let Some(&pw) = power.get(m as usize) else {
                    continue;
                };
                if pw == 0.0 {
                    continue;
                }
                let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
                let c = e1.cross(e2);
                let area = 0.5 * c.length();
                if !(area.is_finite() && area > 0.0) {
                    continue;
                }
                emitters.push(Emitter {
                    p0: p[0],
                    e1,
                    e2,
                    normal: c / (2.0 * area),
                    area,
                    tri: base + i as u32,
                    material: m,
                    two_sided: scene
                        .materials
                        .get(m as usize)
                        .is_some_and(|m| m.double_sided),
                });
                weights.push(f64::from(pw) * f64::from(area));
            }
            base = base.saturating_add(soup.len() as u32);
        }
        let total: f64 = weights.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return AreaLights::default();
        }
        let mut acc = 0.0f64;
        let mut cdf: Vec<f32> = weights
            .iter()
            .map(|w| {
                acc += w;
                (acc / total) as f32
            })
            .collect();
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        AreaLights { emitters, cdf }
    }

    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty()
    }

    /// The emitters in drawing order, each with its cumulative probability and the one
    /// below it (what [`AreaLights::sample`] reads), for the GPU's table.
    #[cfg(feature = "gpu")]
    pub fn table(&self) -> impl Iterator<Item = (&Emitter, f32, f32)> + '_ {
        self.emitters
            .iter()
            .zip(&self.cdf)
            .enumerate()
            .map(|(i, (e, &c))| {
                let below = if i == 0 { 0.0 } else { self.cdf[i - 1] };
                (e, c, below)
            })
    }

    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.emitters.len()
    }

    /// The emitter that `pick` in `[0, 1)` selects and the probability of selecting it.
    fn pick(&self, pick: f32) -> Option<(&Emitter, f32)> {
        let i = self
            .cdf
            .partition_point(|&c| c <= pick)
            .min(self.cdf.len().checked_sub(1)?);
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let p = self.cdf[i] - lo;
        (p > 0.0).then(|| (&self.emitters[i], p))
    }

    /// A point on the lights: the emitter chosen by `pick`, the point by `r` (uniform
    /// in `[0, 1)²`).
    pub fn sample(&self, pick: f32, r: Vec2) -> Option<LightPoint> {
        let (e, p) = self.pick(pick)?;
        let su = r.x.sqrt();
        let (u, v) = (su * (1.0 - r.y), su * r.y);
        Some(LightPoint {
            point: e.p0 + e.e1 * u + e.e2 * v,
            normal: e.normal,
            two_sided: e.two_sided,
            bary: Vec2::new(u, v),
            tri: e.tri,
            material: e.material,
            pdf_area: p / e.area,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn soup(tris: &[([Vec3; 3], u32)]) -> TriangleSoup {
        let mut s = TriangleSoup::new();
        for (p, m) in tris {
            s.positions.push(*p);
            s.normals.push([Vec3::Z; 3]);
            s.uvs.push([Vec2::ZERO; 3]);
            s.material.push(*m);
            s.node.push(0);
        }
        s
    }

    #[test]
    fn picks_by_power_and_area() {
        let scene = Scene {
            materials: vec![
                Material::default(),
                Material {
                    emissive: Vec3::ONE,
                    ..Material::default()
                },
            ],
            ..Scene::default()
        };
        let small = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let big = [Vec3::ZERO, Vec3::X * 3.0, Vec3::Y];
        let st = soup(&[(small, 0), (small, 1)]);
        let dy = soup(&[(big, 1)]);
        let lights = AreaLights::new(&scene, &st, &dy);
        assert_eq!(lights.len(), 2, "the non-emissive triangle is no light");
        // Areas 0.5 and 1.5: a quarter and three quarters of the power.
        let (e, p) = lights.pick(0.1).unwrap();
        assert_eq!((e.tri, p), (1, 0.25));
        let (e, p) = lights.pick(0.3).unwrap();
        assert_eq!((e.tri, p), (2, 0.75));
        let q = lights.sample(0.9, Vec2::new(0.3, 0.6)).unwrap();
        assert!((q.pdf_area - 0.5).abs() < 1e-6);
        assert!(q.point.z == 0.0 && q.point.x >= 0.0 && q.point.y >= 0.0);
        assert!(
            q.point.x / 3.0 + q.point.y <= 1.0 + 1e-6,
            "inside the triangle"
        );
        assert!(AreaLights::new(&scene, &soup(&[(small, 0)]), &TriangleSoup::new()).is_empty());
    }
}
