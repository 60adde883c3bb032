//! The museum's materials (added to the scene once, referred to by index).

use super::*;

pub(super) struct Materials {
    pub(super) floor_light: u32,
    pub(super) floor_dark: u32,
    pub(super) wall: u32,
    pub(super) ceiling: u32,
    pub(super) marble: u32,
    pub(super) gold: u32,
    pub(super) mirror: u32,
    pub(super) chrome: u32,
    pub(super) glass: u32,
    pub(super) bronze: u32,
    pub(super) wood: u32,
    pub(super) baseboard: u32,
    pub(super) canvases: [u32; 7],
    pub(super) chips: [u32; 4],
}

fn add_material(b: &mut Scene, m: Material) -> u32 {
    b.materials.push(m);
    (b.materials.len() - 1) as u32
}

impl Materials {
    pub(super) fn add(b: &mut Scene) -> Materials {
        let mut mat = |name: &str, rgb: [f32; 3], metallic: f32, roughness: f32| {
            add_material(
                b,
                Material {
                    name: Some(name.to_string()),
                    base_color: Vec3::from(rgb).extend(1.0),
                    metallic,
                    roughness,
                    ..Material::default()
                },
            )
        };
        let floor_light = mat("floor-marble-light", [0.82, 0.80, 0.74], 0.0, 0.25);
        let floor_dark = mat("floor-marble-dark", [0.07, 0.07, 0.08], 0.0, 0.25);
        let wall = mat("wall", [0.72, 0.62, 0.48], 0.0, 0.9);
        let ceiling = mat("ceiling", [0.90, 0.90, 0.88], 0.0, 0.9);
        let marble = mat("pillar-marble", [0.88, 0.86, 0.82], 0.0, 0.4);
        let gold = mat("frame-gold", [1.0, 0.78, 0.34], 1.0, 0.25);
        let mirror = mat("mirror", [0.95, 0.95, 0.95], 1.0, 0.0);
        let chrome = mat("chrome", [0.90, 0.90, 0.92], 1.0, 0.02);
        let bronze = mat("bronze", [0.80, 0.50, 0.28], 1.0, 0.3);
        let wood = mat("wood", [0.35, 0.22, 0.12], 0.0, 0.6);
        let baseboard = mat("baseboard", [0.20, 0.15, 0.10], 0.0, 0.5);
        let palette = [
            [0.70, 0.12, 0.10],
            [0.10, 0.25, 0.60],
            [0.85, 0.65, 0.15],
            [0.12, 0.45, 0.22],
            [0.50, 0.20, 0.55],
            [0.90, 0.45, 0.20],
            [0.20, 0.55, 0.60],
        ];
        let mut canvases = [0; 7];
        for (i, c) in palette.iter().enumerate() {
            canvases[i] = mat(&format!("canvas-{i}"), *c, 0.0, 0.8);
        }
        let glass = add_material(
            b,
            Material {
                name: Some("glass".into()),
                base_color: Vec4::new(0.95, 0.97, 1.0, 1.0),
                metallic: 0.0,
                roughness: 0.0,
                transmission: 1.0,
                ior: 1.5,
                ..Material::default()
            },
        );
        // Thin triangles seen from both sides.
        let mut chip = |name: &str, rgb: [f32; 3], metallic: f32, roughness: f32| {
            add_material(
                b,
                Material {
                    name: Some(name.to_string()),
                    base_color: Vec3::from(rgb).extend(1.0),
                    metallic,
                    roughness,
                    double_sided: true,
                    ..Material::default()
                },
            )
        };
        let chips = [
            chip("chip-red", [0.85, 0.12, 0.08], 0.0, 0.4),
            chip("chip-gold", [1.0, 0.80, 0.40], 1.0, 0.15),
            chip("chip-blue", [0.12, 0.30, 0.85], 0.0, 0.4),
            chip("chip-white", [0.92, 0.92, 0.90], 0.0, 0.4),
        ];
        Materials {
            floor_light,
            floor_dark,
            wall,
            ceiling,
            marble,
            gold,
            mirror,
            chrome,
            glass,
            bronze,
            wood,
            baseboard,
            canvases,
            chips,
        }
    }
}
