"""Engine tests, one folder per stage of ``ctui/engine`` (core, io, segment, mesh, measure, render,
vessel, actions): outcomes against known truths (analytic phantoms, reference labels in
../shared/data, rendered pixels)."""
