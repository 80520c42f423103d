"""``kernel_loader.cached`` after a kernel module is rewritten with the same text (a
checkout, a reinstall): its cache file is older than the source, yet made from the same
text, so the load would link it; the check must call it warm (the gates otherwise keep
taking the slow route for good), touch it, and still call a changed text cold."""

from __future__ import annotations

import hashlib
import marshal
import os
import time

import pytest

from mitld_lp.util import kernel_files, kernel_loader, kernel_sources

NOW = time.time_ns()
OLD = NOW - 10**12  # the cache file written a thousand seconds ago
NEW = NOW - 10**10  # the source rewritten ten seconds ago


def _setup(tmp_path, monkeypatch, text: str, made_from: str):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(kernel_sources, "_sources", {})  # hashes read afresh
    source = tmp_path / "src" / "some_kernels.py"
    source.parent.mkdir()
    source.write_text(text)
    (directory,) = kernel_files.directories(str(source))
    directory.mkdir(parents=True)
    digest = hashlib.sha256(made_from.encode()).hexdigest()  # as the loader keys it
    key = repr(("format", ("parts",), "some_kernels", "sweep", digest, "code", ())).encode()
    cache = directory / kernel_files.file_name(str(source), "sweep", (("int",),))
    kernel_files.write(cache, kernel_files.pack(marshal.dumps({"key": key, "sources": ()}),
                                                b"object code"))
    os.utime(cache, ns=(OLD, OLD))
    os.utime(source, ns=(NEW, NEW))
    return source, cache


def test_an_older_file_made_from_the_same_text_is_warm_and_touched(
        tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = "def sweep(x):\n    return x\n"
    source, cache = _setup(tmp_path, monkeypatch, text, made_from=text)
    assert kernel_loader.cached(str(source), "sweep")
    assert cache.stat().st_mtime_ns >= source.stat().st_mtime_ns  # the fast test from now on


def test_an_older_file_made_from_another_text_is_cold(
        tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    source, cache = _setup(tmp_path, monkeypatch, "def sweep(x):\n    return x + 1\n",
                           made_from="def sweep(x):\n    return x\n")
    assert not kernel_loader.cached(str(source), "sweep")
    assert cache.stat().st_mtime_ns == OLD  # left as it was


def test_a_damaged_older_file_is_cold(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = "def sweep(x):\n    return x\n"
    source, cache = _setup(tmp_path, monkeypatch, text, made_from=text)
    cache.write_bytes(cache.read_bytes()[:-3])  # its checksum no longer holds
    os.utime(cache, ns=(OLD, OLD))
    assert not kernel_loader.cached(str(source), "sweep")
