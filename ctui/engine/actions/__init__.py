"""One public function per user action, with typed results (``.to_dict()`` -> JSON through
:mod:`ctui.engine.core.jsonio`). CLI commands and TUI screens call these, so both give the
same numbers; every default lives in :mod:`ctui.engine.actions.defaults`.

=====================  ==============================================  ===================
action                 function                                        result
=====================  ==============================================  ===================
open anything          :func:`.opened.open_input`                       :class:`.opened.Opened`
describe a series      :func:`.info.describe_series`                    (Volume, dict)
segment, propagate     :func:`.segment.segment`                         :class:`.segment.SegmentResult`
objects -> meshes      :func:`.mesh.mesh_objects`                       :class:`.mesh.MeshResult`
measure an object      :func:`.measure.measure_object`                  :class:`.measure.MeasureResult`
render a view          :func:`.render.render_view`                      :class:`.render.RenderResult`
drift check            :func:`.drift.drift_check`                       :class:`.drift.DriftResult`
save a project         :func:`.project.save_project`, ``new_project``   Path / Project
export                 :func:`.export.export`, ``formats.FORMATS``      :class:`.export.ExportResult`
batch                  :func:`.batch.run_batch`                         rows of RESULTS.csv
loader option text     :func:`.options.load_options`                    dict
=====================  ==============================================  ===================

Import the submodule you need (``from ctui.engine.actions.measure import measure_object``):
this ``__init__`` imports nothing, so a command's ``--help`` stays fast.
"""
