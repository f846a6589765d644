"""Names and terminal text (standard library only: the CLI imports it before anything heavy).

A name (case, DOF, contact, platform, component, method) is non-empty printable text; a text
shown on a terminal has its control characters escaped, so that a name holding an ANSI or OSC
escape sequence, a bidi override or a NUL is printed as ``\\x1b[31m`` and never acts on the
terminal.
"""

from __future__ import annotations

import unicodedata

from slipstep.errors import InputError

MAX_NAME_LENGTH = 200
_UNSAFE = ("Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn")  # control, format, line/paragraph separators, ...


def check_name(field: str, name) -> str:
    """A name (case, DOF, contact, platform, component, method): non-empty text of printable
    characters (no control, format or line-break characters), at most MAX_NAME_LENGTH long."""
    if not isinstance(name, str):
        raise InputError(field, f"is {name!r}, not text", "give a name in quotes")
    if not name.strip():
        raise InputError(field, "is empty" if not name else "is blank", "give a non-empty name")
    if len(name) > MAX_NAME_LENGTH:
        raise InputError(field, f"is {len(name)} characters long", f"give a name of at most {MAX_NAME_LENGTH}")
    for ch in name:
        if unicodedata.category(ch) in _UNSAFE:
            raise InputError(
                field,
                f"'{escape_text(name)}' contains the control character {escape_text(ch)}",
                "use printable characters only",
            )
    return name


def escape_text(text) -> str:
    """``text`` with every control, format or line-break character written as an escape
    (\\x1b, \\u202e): safe to print on a terminal."""
    return "".join(
        ch
        if unicodedata.category(ch) not in _UNSAFE
        else (f"\\x{ord(ch):02x}" if ord(ch) < 256 else f"\\u{ord(ch):04x}" if ord(ch) < 65536 else f"\\U{ord(ch):08x}")
        for ch in str(text)
    )
