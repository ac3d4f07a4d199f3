"""ssl_core: SRP-PHAT sound-source localization for small microphone arrays.

Depends only on numpy and scipy so that it runs unchanged on a Raspberry Pi.
Frames: the *array frame* has its origin at the array centre, +x forward,
+y left, +z up (right-handed). Azimuth is counter-clockwise from +x in the
x-y plane, elevation is up from the x-y plane. Angles are radians inside.
"""
from ssl_core.geometry import ArrayGeometry, cube8, cube8_corners, get_array, load_array

__all__ = ["ArrayGeometry", "cube8", "cube8_corners", "get_array", "load_array"]
