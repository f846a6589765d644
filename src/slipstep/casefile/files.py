"""Case files without the model: where the built-in cases are, and reading TOML with errors
that name the file. Light (standard library only) so that ``slipstep cases`` and
``slipstep --help`` need neither numpy nor pydantic; slipstep.casefile.case builds the model."""

from __future__ import annotations

import sys
from pathlib import Path

from slipstep.errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CASES_DIR = Path(__file__).parent / "cases"


def builtin_cases() -> list[str]:
    return sorted(p.stem for p in CASES_DIR.glob("*.toml"))


def case_path(name_or_path) -> Path:
    """The file of a built-in case name (``paper``) or the path given."""
    path = Path(name_or_path)
    if not path.suffix and str(name_or_path) in builtin_cases():
        return CASES_DIR / f"{name_or_path}.toml"
    return path


def case_stem(name_or_path) -> str:
    """The name output files are named after: the built-in case name or the file's stem."""
    text = str(name_or_path)
    if not Path(text).suffix and text in builtin_cases():
        return text
    return Path(text).stem or "case"


def read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InputError(
            "case",
            f"file {str(path)!r} not found",
            f"give a TOML file path or a built-in case name ({', '.join(builtin_cases())})",
        ) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError("case", f"{path} is not valid TOML ({exc})", "fix the TOML syntax") from None
    except UnicodeDecodeError:
        raise InputError("case", f"{path} is not UTF-8 text", "give a TOML text file (UTF-8)") from None
    except (OSError, ValueError) as exc:  # a directory, no permission, a NUL in the path, ...
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise InputError(
            "case", f"{str(path)!r} cannot be read ({reason})", "give a readable TOML file or a built-in case name"
        ) from None
