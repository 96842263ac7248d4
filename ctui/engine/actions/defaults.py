"""Every default of a user action, in one place: the CLI's option defaults and the TUI's
screens read them from here, so both give the same numbers for the same object."""

from __future__ import annotations

from ctui.engine.measure import DEFAULT_SECTION_STEP_MM

#: Distance between cross-sections along a path (mm), for `ctui measure` and the TUI's M screen:
#: the measure package's own default (its package __init__ holds only constants: cheap to import).
SECTION_STEP_MM = DEFAULT_SECTION_STEP_MM
#: Section area estimate: "pv" (partial-volume integral) or "contour" (shoelace).
SECTION_AREA = "pv"
#: Thin-slab averaging of each section along the path (mm; 0 = single planes).
SECTION_AVERAGE_MM = 0.0

#: Object surfaces: "marching-cubes" (smoothed signed distance) or "contours" (connected
#: slice contours); the CLI's --method, the 3D view's c cycle and mesh_objects read the list.
MESH_METHODS = ("marching-cubes", "contours")
MESH_METHOD = MESH_METHODS[0]
#: Contour tiling: "dp" (minimum area) or "greedy".
CONTOUR_TILING = "dp"
#: Taubin smoothing iterations after meshing (0 = none).
MESH_SMOOTH_ITERATIONS = 0

#: Rendering.
RENDER_SIZE = (800, 600)
RENDER_AZIMUTH = 30.0
RENDER_ELEVATION = 15.0
TURNTABLE_FRAMES = 36
ANIMATION_FPS = 15.0
FLY_FRAMES = 48
FLY_FOV_DEG = 70.0
MAX_RENDER_SIDE = 8192
#: A wire view draws at most this many triangles (a decimated copy beyond it: lines that dense draw as a solid,
#: and a 5 M-face wire turntable took minutes on a software renderer)
WIRE_MAX_FACES = 400_000

#: Drift check: running-median fit over this many slices.
DRIFT_FIT = "median"
DRIFT_FIT_WINDOW = 9
DRIFT_ESTIMATE = "centroid"

#: Input kinds by file name.
PROJECT_SUFFIXES = (".ctui", ".ctui.autosave")
LABEL_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".seg.nrrd", ".nhdr")
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off", ".glb", ".gltf")
MRIC_SUFFIXES = (".mric",)
#: ``ctui report --format``: a DICOM SR (TID 1500) over a DICOM-SEG, the measurements as JSON, one CSV row per object
REPORT_FORMATS = ("sr", "json", "csv")
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
