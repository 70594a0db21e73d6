"""All-or-nothing output: write to temporary files beside the targets, then rename them in place."""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import ParameterError

__all__ = ["atomic_outputs", "atomic_folder", "atomic_directory"]


@contextmanager
def atomic_outputs(*targets: Path) -> Iterator[list[Path]]:
    """Yield temporary paths, one per target, and move them onto the targets on success.

    The temporaries live in the target's own folder so that :func:`os.replace` is an atomic
    rename on the same file system. If the body raises, every temporary is removed and no target
    is touched. The targets are replaced in the order given, so pass a header last: a reader never
    sees a new header pointing at missing data.

    Raises
    ------
    ParameterError
        When a target's folder does not exist or a file cannot be written there.
    """
    for target in targets:
        if not target.parent.is_dir():
            raise ParameterError(f"{target}: folder {target.parent} does not exist")
    temps = [t.parent / f".{t.name}.{secrets.token_hex(4)}.part" for t in targets]
    try:
        yield temps
        for temp, target in zip(temps, targets, strict=True):
            os.replace(temp, target)
    except OSError as exc:
        _remove(temps)
        reason = exc.strerror or str(exc)
        raise ParameterError(f"{targets[0]}: cannot write: {reason}") from exc
    except BaseException:
        _remove(temps)
        raise


@contextmanager
def atomic_folder(target: Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``target`` and move it onto ``target`` on success.

    An existing ``target`` folder is replaced as a whole (the caller decides whether it may
    be); if the body raises, the temporary folder and everything in it are removed.

    Raises
    ------
    ParameterError
        When the folder cannot be created there.
    """
    temp = target.parent / f".{target.name}.{secrets.token_hex(4)}.part"
    try:
        temp.mkdir()
    except OSError as exc:
        raise ParameterError(f"{target}: cannot write: {exc.strerror or exc}") from exc
    try:
        yield temp
        old = None
        if target.exists():  # a folder cannot be renamed onto a non-empty one: move it aside
            old = target.parent / f".{target.name}.{secrets.token_hex(4)}.old"
            os.replace(target, old)
        os.replace(temp, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(temp, ignore_errors=True)
        raise


def _remove(paths: list[Path]) -> None:
    for path in paths:
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass  # best effort: the original error is the one worth reporting


@contextmanager
def atomic_directory(target: Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside ``target`` and rename it to ``target`` on success.

    For outputs that are folders (a Zarr store). A reader never sees a half-written folder under
    the final name: while the body runs, only ``.NAME.XXXXXXXX.part`` exists; if the body raises,
    that folder is deleted. With ``overwrite``, an existing ``target`` is first renamed aside and
    deleted after the new folder took its place.

    Raises
    ------
    ParameterError
        When the parent folder does not exist, ``target`` exists and ``overwrite`` is false, or
        the folder cannot be created or renamed.
    """
    if not target.parent.is_dir():
        raise ParameterError(f"{target}: folder {target.parent} does not exist")
    if target.exists() and not overwrite:
        raise ParameterError(f"{target}: already exists (pass overwrite=True or --overwrite)")
    temp = target.parent / f".{target.name}.{secrets.token_hex(4)}.part"
    try:
        temp.mkdir()
    except OSError as exc:
        raise ParameterError(f"{target}: cannot write: {exc.strerror or exc}") from exc
    try:
        yield temp
    except BaseException:
        _remove_tree(temp)
        raise
    try:
        if target.exists():
            aside = target.parent / f".{target.name}.{secrets.token_hex(4)}.old"
            os.replace(target, aside)
            os.replace(temp, target)
            _remove_tree(aside)
        else:
            os.replace(temp, target)
    except OSError as exc:
        _remove_tree(temp)
        raise ParameterError(f"{target}: cannot write: {exc.strerror or exc}") from exc


def _remove_tree(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path, ignore_errors=True)  # best effort, like _remove
    else:
        _remove([path])
