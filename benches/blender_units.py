# Issue 35's acceptance scene, inside Blender: a small scene made as an artist would (a
# grey floor, a back wall, a red and a green box, a 1000 W point light and a 3 W/m² sun,
# a camera), exported with the glTF exporter's default settings (lighting mode
# "Standard": candela and lux) plus lights and camera, then rendered by Cycles with
# direct light only (also exported in the "Unitless" mode, to show what that gives),
# once with the Principled BSDFs as authored and once with each
# replaced by a Lambertian Diffuse BSDF of its colour (subfield's diffuse lobe).
# benches/blender_units.sh runs it, renders the exported file with subfield and compares
# the two per material.
#
# With a fifth argument BOUNCES > 0 (benches/blender_bounces.sh), Cycles renders only the
# Lambertian materials, with BOUNCES diffuse bounces and no clamping, to
# cycles_lambert_bBOUNCES.exr: the reference for `--diffuse-bounces BOUNCES`.
#
# run: blender -b --factory-startup --python benches/blender_units.py -- OUT_DIR W H SPP [BOUNCES]
import bpy, sys, math
from mathutils import Vector

a = sys.argv[sys.argv.index("--") + 1:]
out, W, H, spp = a[0], int(a[1]), int(a[2]), int(a[3])
bounces = int(a[4]) if len(a) > 4 else 0

bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene


def material(name, rgb):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    p = m.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*rgb, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Metallic"].default_value = 0.0
    p.inputs["Specular"].default_value = 0.0
    return m


def add(obj, mat):
    obj.data.materials.append(mat)
    return obj


bpy.ops.mesh.primitive_plane_add(size=12, location=(0, 0, 0))
add(bpy.context.object, material("floor", (0.5, 0.5, 0.5))).name = "floor"
bpy.ops.mesh.primitive_plane_add(size=12, location=(0, 4, 3), rotation=(math.pi / 2, 0, 0))
add(bpy.context.object, material("wall", (0.25, 0.3, 0.6))).name = "wall"
bpy.ops.mesh.primitive_cube_add(size=1.2, location=(-1.4, 0.3, 0.6), rotation=(0, 0, 0.4))
add(bpy.context.object, material("red", (0.7, 0.12, 0.1))).name = "red"
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.3, -0.4, 0.5), rotation=(0, 0, -0.3))
add(bpy.context.object, material("green", (0.15, 0.6, 0.2))).name = "green"

lp = bpy.data.lights.new("lamp", "POINT")
lp.energy = 1000.0  # W
lp.shadow_soft_size = 0.0  # punctual, as glTF's
lo = bpy.data.objects.new("lamp", lp)
sc.collection.objects.link(lo)
lo.location = (0.5, -1.5, 3.5)
sun = bpy.data.lights.new("sun", "SUN")
sun.energy = 3.0  # W/m²
sun.angle = 0.0
so = bpy.data.objects.new("sun", sun)
sc.collection.objects.link(so)
so.rotation_euler = (math.radians(50), 0, math.radians(-30))

cd = bpy.data.cameras.new("camera")
cam = bpy.data.objects.new("camera", cd)
sc.collection.objects.link(cam)
cam.location = (0.5, -7.5, 4.0)
cam.rotation_euler = (Vector((0, 0, 0.6)) - cam.location).to_track_quat("-Z", "Y").to_euler()
sc.camera = cam
sc.render.resolution_x, sc.render.resolution_y = W, H
sc.render.resolution_percentage = 100

# The exporter's defaults; lights and cameras are not exported by default, so asked for.
bpy.ops.export_scene.gltf(filepath=out + "/scene.glb", export_format="GLB",
                          export_cameras=True, export_lights=True)
# The same in the non-default "Unitless" lighting mode (docs/INPUTS.md: 683x too dark).
mode = {"convert_lighting_mode": "COMPAT"} if bpy.app.version < (3, 6, 0) else \
    {"export_import_convert_lighting_mode": "COMPAT"}
bpy.ops.export_scene.gltf(filepath=out + "/scene_unitless.glb", export_format="GLB",
                          export_cameras=True, export_lights=True, **mode)

sc.render.engine = "CYCLES"
cy = sc.cycles
cy.device = "CPU"
cy.samples = spp
cy.use_denoising = False
cy.use_adaptive_sampling = False
cy.max_bounces = bounces  # 0: direct light only: camera, surface, light
cy.diffuse_bounces = bounces
cy.glossy_bounces = cy.transmission_bounces = cy.volume_bounces = cy.transparent_max_bounces = 0
cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0  # no clamping: an unbiased reference
sc.render.threads_mode = "FIXED"
sc.render.threads = 2
sc.render.film_transparent = True
sc.render.image_settings.file_format = "OPEN_EXR"
sc.render.image_settings.color_depth = "32"
sc.view_settings.view_transform = "Standard"
sc.world = bpy.data.worlds.new("black")
sc.world.use_nodes = True
sc.world.node_tree.nodes["Background"].inputs[1].default_value = 0.0

if bounces == 0:
    sc.render.filepath = out + "/cycles_principled.exr"
    bpy.ops.render.render(write_still=True)
for m in bpy.data.materials:
    nt = m.node_tree
    p = nt.nodes.get("Principled BSDF")
    if p is None:
        continue
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = p.inputs["Base Color"].default_value
    d.inputs["Roughness"].default_value = 0.0  # Lambert, not Oren-Nayar
    nt.links.new(d.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
sc.render.filepath = out + ("/cycles_lambert.exr" if bounces == 0 else f"/cycles_lambert_b{bounces}.exr")
bpy.ops.render.render(write_still=True)
