"""The headless engine of ctui: loading, filters, selection, contours, meshes,
rendering, measurement and file formats.

Nothing in this package may import ``textual``, ``rich`` or ``textual_image``
(``tests/architecture/test_engine_imports.py`` checks it in a fresh subprocess). Submodules are
imported on demand; this ``__init__`` stays empty so ``import ctui.engine`` is cheap.
"""
