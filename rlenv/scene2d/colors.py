"""Colours: CSS names, ``"#rrggbb"`` and RGB tuples, and gradients between them (Blueprints').

Shapes are drawn in the RGB colour of their ``color`` (see :mod:`rlenv.scene2d.render`); every
place that takes a colour takes any of these forms::

    to_rgb("purple")            # (128, 0, 128): one of the 148 CSS colour names
    to_rgb("#FF3300")           # (255, 51, 0); "#f30" too
    to_rgb((10, 20, 30))        # (10, 20, 30)
    gradient("purple", "blue", n_steps=20)   # 20 colours from purple to blue, ends exact
"""

from __future__ import annotations

import math
import operator
from collections.abc import Iterable

__all__ = ["CSS_COLORS", "RGB", "Color", "gradient", "to_rgb"]

RGB = tuple[int, int, int]
Color = str | Iterable[int]
"""A CSS colour name, ``"#rrggbb"`` / ``"#rgb"``, or three integers in [0, 255]."""

CSS_COLORS: dict[str, int] = {
    "aliceblue": 0xF0F8FF,
    "antiquewhite": 0xFAEBD7,
    "aqua": 0x00FFFF,
    "aquamarine": 0x7FFFD4,
    "azure": 0xF0FFFF,
    "beige": 0xF5F5DC,
    "bisque": 0xFFE4C4,
    "black": 0x000000,
    "blanchedalmond": 0xFFEBCD,
    "blue": 0x0000FF,
    "blueviolet": 0x8A2BE2,
    "brown": 0xA52A2A,
    "burlywood": 0xDEB887,
    "cadetblue": 0x5F9EA0,
    "chartreuse": 0x7FFF00,
    "chocolate": 0xD2691E,
    "coral": 0xFF7F50,
    "cornflowerblue": 0x6495ED,
    "cornsilk": 0xFFF8DC,
    "crimson": 0xDC143C,
    "cyan": 0x00FFFF,
    "darkblue": 0x00008B,
    "darkcyan": 0x008B8B,
    "darkgoldenrod": 0xB8860B,
    "darkgray": 0xA9A9A9,
    "darkgreen": 0x006400,
    "darkgrey": 0xA9A9A9,
    "darkkhaki": 0xBDB76B,
    "darkmagenta": 0x8B008B,
    "darkolivegreen": 0x556B2F,
    "darkorange": 0xFF8C00,
    "darkorchid": 0x9932CC,
    "darkred": 0x8B0000,
    "darksalmon": 0xE9967A,
    "darkseagreen": 0x8FBC8F,
    "darkslateblue": 0x483D8B,
    "darkslategray": 0x2F4F4F,
    "darkslategrey": 0x2F4F4F,
    "darkturquoise": 0x00CED1,
    "darkviolet": 0x9400D3,
    "deeppink": 0xFF1493,
    "deepskyblue": 0x00BFFF,
    "dimgray": 0x696969,
    "dimgrey": 0x696969,
    "dodgerblue": 0x1E90FF,
    "firebrick": 0xB22222,
    "floralwhite": 0xFFFAF0,
    "forestgreen": 0x228B22,
    "fuchsia": 0xFF00FF,
    "gainsboro": 0xDCDCDC,
    "ghostwhite": 0xF8F8FF,
    "gold": 0xFFD700,
    "goldenrod": 0xDAA520,
    "gray": 0x808080,
    "green": 0x008000,
    "greenyellow": 0xADFF2F,
    "grey": 0x808080,
    "honeydew": 0xF0FFF0,
    "hotpink": 0xFF69B4,
    "indianred": 0xCD5C5C,
    "indigo": 0x4B0082,
    "ivory": 0xFFFFF0,
    "khaki": 0xF0E68C,
    "lavender": 0xE6E6FA,
    "lavenderblush": 0xFFF0F5,
    "lawngreen": 0x7CFC00,
    "lemonchiffon": 0xFFFACD,
    "lightblue": 0xADD8E6,
    "lightcoral": 0xF08080,
    "lightcyan": 0xE0FFFF,
    "lightgoldenrodyellow": 0xFAFAD2,
    "lightgray": 0xD3D3D3,
    "lightgreen": 0x90EE90,
    "lightgrey": 0xD3D3D3,
    "lightpink": 0xFFB6C1,
    "lightsalmon": 0xFFA07A,
    "lightseagreen": 0x20B2AA,
    "lightskyblue": 0x87CEFA,
    "lightslategray": 0x778899,
    "lightslategrey": 0x778899,
    "lightsteelblue": 0xB0C4DE,
    "lightyellow": 0xFFFFE0,
    "lime": 0x00FF00,
    "limegreen": 0x32CD32,
    "linen": 0xFAF0E6,
    "magenta": 0xFF00FF,
    "maroon": 0x800000,
    "mediumaquamarine": 0x66CDAA,
    "mediumblue": 0x0000CD,
    "mediumorchid": 0xBA55D3,
    "mediumpurple": 0x9370DB,
    "mediumseagreen": 0x3CB371,
    "mediumslateblue": 0x7B68EE,
    "mediumspringgreen": 0x00FA9A,
    "mediumturquoise": 0x48D1CC,
    "mediumvioletred": 0xC71585,
    "midnightblue": 0x191970,
    "mintcream": 0xF5FFFA,
    "mistyrose": 0xFFE4E1,
    "moccasin": 0xFFE4B5,
    "navajowhite": 0xFFDEAD,
    "navy": 0x000080,
    "oldlace": 0xFDF5E6,
    "olive": 0x808000,
    "olivedrab": 0x6B8E23,
    "orange": 0xFFA500,
    "orangered": 0xFF4500,
    "orchid": 0xDA70D6,
    "palegoldenrod": 0xEEE8AA,
    "palegreen": 0x98FB98,
    "paleturquoise": 0xAFEEEE,
    "palevioletred": 0xDB7093,
    "papayawhip": 0xFFEFD5,
    "peachpuff": 0xFFDAB9,
    "peru": 0xCD853F,
    "pink": 0xFFC0CB,
    "plum": 0xDDA0DD,
    "powderblue": 0xB0E0E6,
    "purple": 0x800080,
    "rebeccapurple": 0x663399,
    "red": 0xFF0000,
    "rosybrown": 0xBC8F8F,
    "royalblue": 0x4169E1,
    "saddlebrown": 0x8B4513,
    "salmon": 0xFA8072,
    "sandybrown": 0xF4A460,
    "seagreen": 0x2E8B57,
    "seashell": 0xFFF5EE,
    "sienna": 0xA0522D,
    "silver": 0xC0C0C0,
    "skyblue": 0x87CEEB,
    "slateblue": 0x6A5ACD,
    "slategray": 0x708090,
    "slategrey": 0x708090,
    "snow": 0xFFFAFA,
    "springgreen": 0x00FF7F,
    "steelblue": 0x4682B4,
    "tan": 0xD2B48C,
    "teal": 0x008080,
    "thistle": 0xD8BFD8,
    "tomato": 0xFF6347,
    "turquoise": 0x40E0D0,
    "violet": 0xEE82EE,
    "wheat": 0xF5DEB3,
    "white": 0xFFFFFF,
    "whitesmoke": 0xF5F5F5,
    "yellow": 0xFFFF00,
    "yellowgreen": 0x9ACD32,
}
"""The CSS Color Module Level 4 named colours, as ``0xRRGGBB``."""

_HEX_DIGITS = frozenset("0123456789abcdefABCDEF")


def to_rgb(color: Color) -> RGB:
    """The RGB triple of ``color``: a CSS name (any case), ``"#rrggbb"``, ``"#rgb"`` or a triple.

    Raises:
        ValueError: an unknown name, a malformed hex string, or a triple out of [0, 255].
        TypeError: anything else.
    """
    if isinstance(color, str):
        return _parse(color)
    try:
        channels = tuple(color)  # a tuple, a list, a numpy array...
    except TypeError:
        channels = ()
    if len(channels) == 3:
        try:
            rgb = tuple(operator.index(channel) for channel in channels)
        except TypeError:
            raise TypeError(f"a colour's channels are integers, got {color!r:.60}") from None
        if not all(0 <= channel <= 255 for channel in rgb):
            raise ValueError(f"a colour's channels are in [0, 255], got {color!r:.60}")
        return rgb  # type: ignore[return-value]
    raise TypeError(f"a colour is a CSS name, '#rrggbb' or three integers, got {color!r:.60}")


def gradient(*colors: Color, n_steps: int) -> list[RGB]:
    """``n_steps`` colours going evenly through ``colors``, first and last exactly.

    Channels are interpolated linearly between consecutive colours and rounded, so
    ``gradient("purple", "blue", n_steps=20)`` starts at purple's (128, 0, 128) and ends at
    blue's (0, 0, 255); with more colours the steps pass through each of them in turn. A single
    colour gives ``n_steps`` copies of it, and ``n_steps=1`` the first colour.

    Args:
        *colors: one or more colours (see :func:`to_rgb`).
        n_steps: how many colours to return, at least 1.

    Raises:
        ValueError: no colour, ``n_steps`` below 1, or a colour that is not one.
        TypeError: ``n_steps`` is not an integer, or a colour is of the wrong type.
    """
    if not colors:
        raise ValueError("gradient needs at least one colour")
    steps = operator.index(n_steps)
    if steps < 1:
        raise ValueError(f"n_steps must be at least 1, got {n_steps}")
    stops = [to_rgb(color) for color in colors]
    if len(stops) == 1 or steps == 1:
        return [stops[0]] * steps
    segments = len(stops) - 1
    result = []
    for index in range(steps):
        where = index * segments / (steps - 1)
        segment = min(int(where), segments - 1)
        fraction = where - segment
        start, end = stops[segment], stops[segment + 1]
        result.append(
            tuple(  # exact at the stops: a + (b - a) * 1.0 == b for small integers
                math.floor(a + (b - a) * fraction + 0.5) for a, b in zip(start, end, strict=True)
            )
        )
    return result  # type: ignore[return-value]


def _parse(text: str) -> RGB:
    if text.startswith("#"):
        digits = text[1:]
        if len(digits) == 3:
            digits = "".join(digit * 2 for digit in digits)
        if len(digits) != 6 or not _HEX_DIGITS.issuperset(digits):
            raise ValueError(f"{text!r:.40} is not a '#rrggbb' colour")
        value = int(digits, 16)
    else:
        found = CSS_COLORS.get(text.lower())
        if found is None:
            raise ValueError(
                f"{text!r:.40} is not a CSS colour name (such as 'purple', "
                "'steelblue') nor '#rrggbb'"
            )
        value = found
    return (value >> 16, (value >> 8) & 0xFF, value & 0xFF)
