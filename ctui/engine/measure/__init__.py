"""measure stage: volumes, centrelines, cross-sections.

Modules, bottom to top (imports point down only): paths, fields, planes, report, flags,
sections, centreline, between, stats, summary. measure imports only ``core`` and ``mesh``.
"""

#: Distance between cross-sections along a path (mm): the one default of `ctui measure`,
#: the TUI's measure screen and :func:`ctui.engine.measure.sections.sections_along_path`.
DEFAULT_SECTION_STEP_MM = 0.5
