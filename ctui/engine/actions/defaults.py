"""Every default of a user action, in one place: the CLI's option defaults and the TUI's
screens read them from here, so both give the same numbers for the same object."""

from __future__ import annotations

from ctui.engine.io.suffixes import LABELMAP_SUFFIXES
from ctui.engine.core.rendermodes import ANTIALIAS, FRAMES
from ctui.engine.measure import DEFAULT_SECTION_STEP_MM
from ctui.engine.mesh import CONTOUR_TILINGS  # the mesh package's list (plain data)
# propagation's defaults and lists, defined in the segment package (plain data) and read here by the CLI
from ctui.engine.segment import (CONNECTIVITIES, CONNECTIVITY, DIRECTION, DIRECTIONS, DOMAIN, DOMAINS,  # noqa: F401
                                 LEAK_FACTOR, MIN_AREA, NEIGHBOURHOOD, PROPAGATION_MODE, PROPAGATION_MODES)

#: Distance between cross-sections along a path (mm), for `ctui measure` and the TUI's M screen:
#: the measure package's own default (its package __init__ holds only constants: cheap to import).
SECTION_STEP_MM = DEFAULT_SECTION_STEP_MM
#: Section area estimate: "pv" (partial-volume integral) or "contour" (shoelace).
SECTION_AREAS = ("pv", "contour")
SECTION_AREA = SECTION_AREAS[0]
#: Thin-slab averaging of each section along the path (mm; 0 = single planes).
SECTION_AVERAGE_MM = 0.0

#: Object surfaces: "marching-cubes" (smoothed signed distance) or "contours" (connected
#: slice contours); the CLI's --method, the 3D view's c cycle and mesh_objects read the list.
MESH_METHODS = ("marching-cubes", "contours")
MESH_METHOD = MESH_METHODS[0]
#: Contour tiling: "dp" (minimum area) or "greedy".
CONTOUR_TILING = CONTOUR_TILINGS[0]
#: Taubin smoothing iterations after meshing (0 = none).
MESH_SMOOTH_ITERATIONS = 0

#: Rendering.
RENDER_SIZE = (800, 600)
RENDER_AZIMUTH = 30.0
RENDER_ELEVATION = 15.0
RENDER_ROLL = 0.0
RENDER_ZOOM = 1.0  # 1: the objects fit the image
RENDER_ANTIALIAS = ANTIALIAS[0]  # ANTIALIAS: core.rendermodes' list
RENDER_FRAME = FRAMES[0]  # "auto": the objects in surface modes, the volume in volume modes
TURNTABLE_FRAMES = 36
ANIMATION_FPS = 15.0
FLY_FRAMES = 48
FLY_FOV_DEG = 70.0
MAX_RENDER_SIDE = 8192
#: A wire view draws at most this many triangles (a decimated copy beyond it: lines that dense draw as a solid,
#: and a 5 M-face wire turntable took minutes on a software renderer)
WIRE_MAX_FACES = 400_000

#: Drift check: running-median fit over this many slices.
DRIFT_FITS = ("median", "poly")
DRIFT_FIT = DRIFT_FITS[0]
DRIFT_FIT_WINDOW = 9
DRIFT_ESTIMATES = ("centroid", "phase")
DRIFT_ESTIMATE = DRIFT_ESTIMATES[0]

#: Input kinds by file name.
PROJECT_SUFFIXES = (".ctui", ".ctui.autosave")
LABEL_SUFFIXES = LABELMAP_SUFFIXES
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off", ".glb", ".gltf")
MRIC_SUFFIXES = (".mric",)
#: ``ctui report --format``: a DICOM SR (TID 1500) over a DICOM-SEG, the measurements as JSON, one CSV row per object
REPORT_FORMATS = ("sr", "json", "csv")
REPORT_FORMAT = REPORT_FORMATS[0]
#: ``ctui report --sections``: the path's sections in a report: the extreme ones (the first: default) or all
REPORT_SECTIONS = ("extremes", "all")

#: A 3D edit (island, scissors, smoothing) that would remove more than this share of the object is
#: shown (the voxels drawn in red, voxels and mL) and asked about before it is done (the TUI).
EDIT_CONFIRM_SHARE = 0.25
#: Names offered for an object (the TUI's N): common structures under their TotalSegmentator names, so
#: exports and reports read alike; any other name can still be typed.
STRUCTURE_NAMES = ("liver", "spleen", "kidney_left", "kidney_right", "pancreas", "gallbladder", "stomach",
                   "aorta", "inferior_vena_cava", "portal_vein_and_splenic_vein", "urinary_bladder",
                   "lung_left", "lung_right", "heart", "brain", "lateral_ventricles", "tumor")

#: `ctui segment` (and the TUI's S/G): the method (a name of actions.segment.METHODS); the rest of
#: SegmentOptions' propagation defaults are the segment package's (imported above).
SEGMENT_METHOD = "fill"
#: level set: corners sharper than this (mm) are smoothed, necks under about twice it blocked
LEVELSET_CURVATURE_MM = 0.5
#: islands under this many voxels are removed from each object (0: none)
MIN_ISLAND_VOXELS = 0
#: `ctui edit --cut`: which side of the box or polygon goes
CUT_SIDES = ("inside", "outside")

#: `ctui auto`: the engine, its task, the device, and how its classes join the objects there
#: (the registries with their help: actions.auto.ENGINES, DEVICES, MERGE)
AUTO_ENGINE = "totalsegmentator"
AUTO_TASK = "total"
AUTO_DEVICE = "cpu"
AUTO_MERGE = "add"

#: `ctui vessel`: the lumen's value range ("auto": from the start voxel) and which lumen is followed
VESSEL_RANGE = "auto"
VESSEL_LUMEN = "contrast"

#: `ctui demo`: the phantom's noise (random seed, sigma in HU)
DEMO_SEED = 0
DEMO_NOISE_HU = 8.0

#: `ctui web`: where the server listens (this machine only by default)
WEB_HOST = "127.0.0.1"
WEB_PORT = 8000
