# One Blender Cycles still of a glTF file, set up to compare with `subfield render` (the
# README's docs/cycles-vs-subfield-2.png). Blender 3.4's own glTF importer, CPU, no diffuse
# bounce, 4 glossy/transmission bounces, no denoising, no adaptive sampling, linear EXR,
# a transparent film (misses have alpha 0, as ours do).
#
# run: blender -b --factory-startup --python benches/cycles_still.py -- \
#          SCENE OUT.exr W H SPP FRAME [options]
# options (all optional):
#   --world L          uniform world radiance (our ambient term is 0.05 × albedo, unoccluded)
#   --light-scale K    multiply the importer's point/spot power by K (default 1). The
#                      importer reads glTF candela as photometric (W = cd·4π/683), as
#                      subfield does since issue 35; K = 683 matches files written by
#                      subfield before then, whose numbers were W/sr
#   --look-from X,Y,Z --look-at X,Y,Z --yfov DEG
#                      a camera at glTF coordinates (else the file's first camera)
#   --sun              subfield's default light: directional, irradiance π, from over the
#                      camera's shoulder (for files with no light)
#   --specular S       set every Principled BSDF's Specular to S (the importer's is 0.5)
#   --lambert          replace every non-emissive Principled BSDF by a Lambertian Diffuse
#                      BSDF of its base colour (subfield's diffuse lobe; docs/IMAGES.md)
# Square pixels with the vertical field of view kept, as subfield does.
import bpy, sys, json, math, struct
import numpy
if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Debian's Blender 3.4 importer still names numpy.bool
from mathutils import Vector

a = sys.argv[sys.argv.index("--") + 1:]
scene_path, out = a[0], a[1]
W, H, spp, frame = int(a[2]), int(a[3]), int(a[4]), int(a[5])
opts, i = {}, 6
while i < len(a):
    if a[i] in ("--sun", "--lambert"):
        opts[a[i].lstrip("-")] = True
        i += 1
    else:
        opts[a[i].lstrip("-")] = a[i + 1]
        i += 2
world = float(opts.get("world", 0.0))
light_scale = float(opts.get("light-scale", 1.0))


def gltf_json(path):
    data = open(path, "rb").read()
    if data[:4] == b"glTF":
        return json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])
    return json.loads(data)


def gl(v):  # glTF Y-up -> Blender Z-up, as the importer converts
    x, y, z = map(float, v.split(","))
    return Vector((x, -z, y))


js = gltf_json(scene_path)
bpy.ops.wm.read_factory_settings(use_empty=True)
try:  # the importer turns animation time into frames at the scene's rate: match ours
    bpy.context.scene.render.fps = int(round(float(js["scenes"][js.get("scene", 0)]["extras"]["fps"])))
except (KeyError, IndexError, TypeError, ValueError):
    pass  # 24, subfield's default too
bpy.ops.import_scene.gltf(filepath=scene_path)
sc = bpy.context.scene

if "look-from" in opts:
    frm, at = gl(opts["look-from"]), gl(opts["look-at"])
    cd = bpy.data.cameras.new("cam")
    cd.sensor_fit = "VERTICAL"
    cd.angle_y = math.radians(float(opts.get("yfov", 45.0)))
    cam = bpy.data.objects.new("cam", cd)
    sc.collection.objects.link(cam)
    cam.location = frm
    cam.rotation_euler = (at - frm).to_track_quat("-Z", "Y").to_euler()
    sc.camera = cam
else:
    cams = [o for o in sc.objects if o.type == "CAMERA"]
    sc.camera = cams[0]
    for o in cams:
        o.data.sensor_fit = "VERTICAL"
        o.data.angle_y = js["cameras"][0]["perspective"]["yfov"]

for o in sc.objects:
    if o.type == "LIGHT" and o.data.type in ("POINT", "SPOT"):
        o.data.energy *= light_scale
        o.data.shadow_soft_size = 0.0  # punctual, as in the file

sc.render.engine = "CYCLES"
cy = sc.cycles
cy.device = "CPU"
cy.samples = spp
cy.use_denoising = False
cy.use_adaptive_sampling = False
cy.max_bounces = 4
cy.diffuse_bounces = 0
cy.glossy_bounces = 4
cy.transmission_bounces = 4
cy.transparent_max_bounces = 4
cy.volume_bounces = 0
sc.render.threads_mode = "FIXED"
sc.render.threads = 2
sc.render.resolution_x, sc.render.resolution_y = W, H
sc.render.resolution_percentage = 100
sc.render.film_transparent = True
sc.render.image_settings.file_format = "OPEN_EXR"
sc.render.image_settings.color_depth = "16"
sc.view_settings.view_transform = "Standard"
if sc.world is None:
    sc.world = bpy.data.worlds.new("w")
sc.world.use_nodes = True
bg = sc.world.node_tree.nodes.get("Background")
if bg:
    bg.inputs[0].default_value = (1, 1, 1, 1)
    bg.inputs[1].default_value = world
if opts.get("sun"):
    bpy.context.view_layer.update()
    towards = (sc.camera.matrix_world.to_3x3() @ Vector((-0.4, 0.6, 0.7))).normalized()
    ld = bpy.data.lights.new("sun", "SUN")
    ld.energy = math.pi
    ld.angle = 0.0
    lo = bpy.data.objects.new("sun", ld)
    sc.collection.objects.link(lo)
    lo.rotation_euler = towards.to_track_quat("Z", "Y").to_euler()
for mat in bpy.data.materials:
    if not mat.use_nodes:
        continue
    nt = mat.node_tree
    for nd in list(nt.nodes):
        if nd.type != "BSDF_PRINCIPLED":
            continue
        if "specular" in opts:
            nd.inputs["Specular"].default_value = float(opts["specular"])
        emits = max(nd.inputs["Emission"].default_value[:3]) > 0
        if opts.get("lambert") and not emits and not nd.inputs["Base Color"].is_linked:
            d = nt.nodes.new("ShaderNodeBsdfDiffuse")
            d.inputs["Color"].default_value = nd.inputs["Base Color"].default_value
            d.inputs["Roughness"].default_value = 0.0  # Lambert, not Oren-Nayar
            for o in [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]:
                nt.links.new(d.outputs[0], o.inputs["Surface"])
sc.frame_set(frame)
sc.render.filepath = out
bpy.ops.render.render(write_still=True)
