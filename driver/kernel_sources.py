"""Which source files compiled (numba) code can depend on, and a key over their contents.

numba revalidates a cached function against its own source file only; a kernel or a
constant it takes from another module can change under it. The cache folder is therefore
named after a hash of every module that uses numba and every package module those import,
transitively (``from .x import y``, ``from .. import x``, ``import gyrostar.x``) — and of no
other: an edit to the command line, the plots or the flatsat runner keeps the cache, an edit
to a kernel or to anything a kernel module imports starts a fresh one.

Plain text scanning (no ``ast``, no imports): it runs on every ``import gyrostar``.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

_FROM = re.compile(r"^[ \t]*from[ \t]+([.\w]+)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]*)", re.MULTILINE)
_COMMENT = re.compile(r"#[^\n]*")
_IMPORT = re.compile(r"^[ \t]*import[ \t]+([\w.]+(?:[ \t]*,[ \t]*[\w.]+)*)", re.MULTILINE)
_IMPORTS_NUMBA = re.compile(r"^[ \t]*(?:from[ \t]+numba\b|import[ \t]+numba\b)", re.MULTILINE)


def _uses_numba(text: str) -> bool:
    """A module that imports numba, or names njit (a decorator handed on through another module)."""
    return "njit" in text or ("numba" in text and _IMPORTS_NUMBA.search(text) is not None)


def package_modules(roots: list[tuple[str, Path]]) -> dict[str, Path]:
    """Module name → file for every ``.py`` under each ``(package name, folder)`` root
    (tests and conftest files left out: they hold no kernels)."""
    mods: dict[str, Path] = {}
    for pkg, folder in roots:
        for p in sorted(folder.rglob("*.py")):
            if p.name == "conftest.py" or p.name.startswith("test_"):
                continue
            parts = list(p.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            mods[".".join([pkg, *parts])] = p
    return mods


def _with_packages(name: str, mods: dict[str, Path]) -> set[str]:
    """Module ``name`` and the packages above it that are in ``mods`` (their ``__init__``
    runs first and may set what it uses)."""
    found = set()
    while name:
        if name in mods:
            found.add(name)
        name = name.rpartition(".")[0]
    return found


def _imported(name: str, path: Path, text: str, mods: dict[str, Path]) -> set[str]:
    """Package modules that module ``name`` (file ``path``, source ``text``) imports."""
    here = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def add(target: str) -> None:
        found.update(_with_packages(target, mods))

    for src, names in _FROM.findall(text):
        dots = len(src) - len(src.lstrip("."))
        if dots:
            base = here
            for _ in range(dots - 1):
                base = base.rpartition(".")[0]
            target = ".".join(s for s in (base, src[dots:]) if s)
        else:
            target = src
        add(target)
        for item in _COMMENT.sub("", names).strip("()").replace("\n", " ").split(","):
            item = item.split(" as ")[0].strip()
            if item and f"{target}.{item}" in mods:
                found.add(f"{target}.{item}")
    for group in _IMPORT.findall(text):
        for item in group.split(","):
            add(item.strip())
    return found


def kernel_closure(mods: dict[str, Path]) -> list[str]:
    """Names (sorted) of the modules that use numba and of every package module they
    import, transitively."""
    texts: dict[str, str] = {}
    for name, path in mods.items():
        try:
            texts[name] = path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            texts[name] = ""
    seen: set[str] = set()
    for name, text in texts.items():
        if _uses_numba(text):
            seen |= _with_packages(name, mods)
    todo = sorted(seen)
    while todo:
        name = todo.pop()
        for dep in _imported(name, mods[name], texts[name], mods):
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return sorted(seen)


def kernel_sources_key(roots: list[tuple[str, Path]]) -> str:
    """Hex SHA-256 over the names and bytes of :func:`kernel_closure`'s modules."""
    mods = package_modules(roots)
    h = hashlib.sha256()
    for name in kernel_closure(mods):
        h.update(name.encode() + b"\0")
        try:
            h.update(mods[name].read_bytes())
        except OSError:
            pass
    return h.hexdigest()
