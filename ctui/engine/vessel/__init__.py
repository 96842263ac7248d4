"""Vessels from a start, waypoints and ends (``ctui vessel``): a minimal path on a speed map
(:mod:`.path`), a colliding-fronts core along each leg, growth section by section in planes
normal to the path (:mod:`.grow`), and the report along the path.

Sits between ``actions`` and ``measure`` in the engine's layers: it uses the measure
package's path geometry and sections, and the segmentation layer's nothing (its own growth).
"""
