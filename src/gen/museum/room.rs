//! The static part: room, pillars, paintings, mirror, pedestals, benches, baseboard.

use super::*;

pub(super) fn build_static(b: &mut Scene, m: &Materials, plan: &Plan) {
    let (h, top) = (ROOM_HALF, ROOM_HEIGHT);
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);

    // Room shell: checkered floor, ceiling, walls facing inwards, baseboard.
    let n = plan.shell;
    let rows = wall_rows(n);
    let (mut light, mut dark) = (Part::default(), Part::default());
    let cell = 2.0 * h / n as f32;
    for i in 0..n {
        for j in 0..n {
            let o = Vec3::new(-h + i as f32 * cell, 0.0, -h + j as f32 * cell);
            let tile = if (i + j) % 2 == 0 {
                &mut light
            } else {
                &mut dark
            };
            tile.grid(o, z * cell, x * cell, 1, 1);
        }
    }
    let mut ceiling = Part::default();
    ceiling.grid(Vec3::new(-h, top, -h), x * 2.0 * h, z * 2.0 * h, n, n);
    let mut walls = Part::default();
    let (w, up) = (2.0 * h, y * top);
    walls.grid(Vec3::new(-h, 0.0, -h), x * w, up, n, rows); // back, faces +Z
    walls.grid(Vec3::new(-h, 0.0, h), up, x * w, rows, n); // front, faces -Z
    walls.grid(Vec3::new(-h, 0.0, -h), up, z * w, rows, n); // left, faces +X
    walls.grid(Vec3::new(h, 0.0, -h), z * w, up, n, rows); // right, faces -X
    let mut board = Part::default();
    let quads = plan.baseboard / 2;
    let (inset, height) = (0.02, y * 0.2);
    let sides = [
        (Vec3::new(-h, 0.0, -h + inset), x * w), // back
        (Vec3::new(h, 0.0, h - inset), -x * w),  // front
        (Vec3::new(-h + inset, 0.0, h), -z * w), // left
        (Vec3::new(h - inset, 0.0, -h), z * w),  // right
    ];
    for (k, (o, du)) in sides.into_iter().enumerate() {
        let q = quads / 4 + usize::from(k < quads % 4);
        board.band(o, du, height, q, k == 3 && plan.baseboard % 2 == 1);
    }
    let room = add_mesh(
        b,
        Mesh {
            name: Some("room".into()),
            // A 1 × 1 floor has no dark tile: empty parts are left out.
            primitives: [
                (light, m.floor_light),
                (dark, m.floor_dark),
                (ceiling, m.ceiling),
                (walls, m.wall),
                (board, m.baseboard),
            ]
            .into_iter()
            .filter(|(part, _)| !part.indices.is_empty())
            .map(|(part, material)| part.primitive(material))
            .collect(),
            weights: Vec::new(),
        },
    );
    add_root(b, node("room", room, Vec3::ZERO, Quat::IDENTITY));

    // Pillars: one mesh, four nodes.
    let (column, blocks) = pillar(plan.pillar);
    let pillar_mesh = add_mesh(
        b,
        Mesh {
            name: Some("pillar".into()),
            primitives: vec![column.primitive(m.marble), blocks.primitive(m.marble)],
            weights: Vec::new(),
        },
    );
    for (i, p) in PILLARS.iter().enumerate() {
        let at = Vec3::new(p.x, 0.0, p.y);
        add_root(
            b,
            node(&format!("pillar-{i}"), pillar_mesh, at, Quat::IDENTITY),
        );
    }

    // Paintings and the mirror: local +Z turned to face into the room, 1 cm off the wall.
    let turn = |deg: f32| Quat::from_rotation_y(deg.to_radians());
    let off = 0.01;
    let hangs: [(&str, Vec3, Quat, f32, f32); 8] = [
        (
            "painting-0",
            Vec3::new(-4.5, 3.2, -h + off),
            turn(0.0),
            3.0,
            2.0,
        ),
        (
            "painting-1",
            Vec3::new(0.0, 3.4, -h + off),
            turn(0.0),
            3.6,
            2.6,
        ),
        (
            "painting-2",
            Vec3::new(4.5, 3.2, -h + off),
            turn(0.0),
            3.0,
            2.0,
        ),
        (
            "painting-3",
            Vec3::new(h - off, 3.2, -3.5),
            turn(-90.0),
            2.6,
            1.8,
        ),
        (
            "painting-4",
            Vec3::new(h - off, 3.2, 3.5),
            turn(-90.0),
            2.6,
            1.8,
        ),
        (
            "painting-5",
            Vec3::new(-4.5, 3.2, h - off),
            turn(180.0),
            3.0,
            2.0,
        ),
        (
            "painting-6",
            Vec3::new(4.5, 3.2, h - off),
            turn(180.0),
            3.0,
            2.0,
        ),
        (
            "mirror",
            Vec3::new(-h + off, 3.6, 0.0),
            turn(90.0),
            6.0,
            3.6,
        ),
    ];
    for (i, (name, at, rot, w, hgt)) in hangs.into_iter().enumerate() {
        let canvas = m.canvases.get(i).copied().unwrap_or(m.mirror);
        let mut mesh = framed(w, hgt, canvas, m.gold);
        mesh.name = Some(name.to_string());
        let mesh = add_mesh(b, mesh);
        add_root(b, node(name, mesh, at, rot));
    }

    // Pedestals with a glass sphere, a chrome sphere and a bronze torus.
    let mut block = Part::default();
    block.cuboid(Vec3::new(-0.4, 0.0, -0.4), Vec3::new(0.4, 1.0, 0.4));
    let pedestal = add_mesh(
        b,
        Mesh {
            name: Some("pedestal".into()),
            primitives: vec![block.primitive(m.wood)],
            weights: Vec::new(),
        },
    );
    let stands = [
        Vec3::new(-3.5, 0.0, 4.0),
        Vec3::new(4.2, 0.0, 2.5),
        Vec3::new(-4.0, 0.0, -3.5),
    ];
    for (i, at) in stands.iter().enumerate() {
        add_root(
            b,
            node(&format!("pedestal-{i}"), pedestal, *at, Quat::IDENTITY),
        );
    }
    for (name, mat, at) in [
        ("glass-sphere", m.glass, stands[0]),
        ("chrome-sphere", m.chrome, stands[1]),
    ] {
        let mesh = add_mesh(
            b,
            Mesh {
                name: Some(name.into()),
                primitives: vec![sphere(0.7, plan.sphere).primitive(mat)],
                weights: Vec::new(),
            },
        );
        add_root(b, node(name, mesh, at + Vec3::Y * 1.7, Quat::IDENTITY));
    }
    let ring = add_mesh(
        b,
        Mesh {
            name: Some("torus".into()),
            primitives: vec![torus(plan.torus).primitive(m.bronze)],
            weights: Vec::new(),
        },
    );
    let stand_up = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(std::f32::consts::FRAC_PI_2);
    add_root(b, node("torus", ring, stands[2] + Vec3::Y * 1.75, stand_up));

    // Benches: a seat on two legs, one mesh, two nodes.
    let mut bench = Part::default();
    bench.cuboid(Vec3::new(-1.2, 0.42, -0.3), Vec3::new(1.2, 0.5, 0.3));
    bench.cuboid(Vec3::new(-1.0, 0.0, -0.25), Vec3::new(-0.9, 0.42, 0.25));
    bench.cuboid(Vec3::new(0.9, 0.0, -0.25), Vec3::new(1.0, 0.42, 0.25));
    let bench = add_mesh(
        b,
        Mesh {
            name: Some("bench".into()),
            primitives: vec![bench.primitive(m.wood)],
            weights: Vec::new(),
        },
    );
    add_root(
        b,
        node("bench-0", bench, Vec3::new(0.0, 0.0, -7.2), Quat::IDENTITY),
    );
    add_root(
        b,
        node("bench-1", bench, Vec3::new(7.6, 0.0, 0.0), turn(90.0)),
    );
}
