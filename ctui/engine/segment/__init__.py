"""segment stage.

Propagation's defaults and choice lists, one definition each (plain data: ``ctui --help`` reads them
through ``actions.defaults`` without loading numpy): :class:`.propagate.PropagationSettings`,
``actions.segment.SegmentOptions``, the CLI and the TUI read these names.
"""

#: in-slice connectivity of the fills (pixels)
CONNECTIVITIES = (4, 8)
CONNECTIVITY = 8
#: which way propagation goes from the seed's slice
DIRECTIONS = ("both", "forward", "backward")
DIRECTION = DIRECTIONS[0]
#: "slice": slice by slice; "3d": one pass in 3D
PROPAGATION_MODES = ("slice", "3d")
PROPAGATION_MODE = PROPAGATION_MODES[0]
#: each slice's fill stays within the previous slice's object grown by this many pixels
NEIGHBOURHOOD = 2
#: smallest accepted object slice (pixels)
MIN_AREA = 5
#: slice mode's leak guard: a slice whose area grows more than this many times the previous one stops
LEAK_FACTOR = 2.5
#: the pipeline's value domain: "hu" (data units) or "window8" (uint8 windowed values)
DOMAINS = ("hu", "window8")
DOMAIN = DOMAINS[0]
