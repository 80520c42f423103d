"""The UMB archive's members read from its tar headers, pax extended headers included
(prism-copy): a member named by a pax ``path`` record (Storm writes one for a label
whose name does not fit the ustar header) is found where :mod:`tarfile` finds it, and an
archive with a pax record this reader does not take still gets :mod:`tarfile`'s answer."""

from __future__ import annotations

import importlib.util
import io
import tarfile
from pathlib import Path

import pytest

from mitld_lp.worlds import prism_archive
from mitld_lp.worlds.prism_archive import Member, members, read_member

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")


def _tarfile_view(path: Path) -> dict[str, Member]:
    with tarfile.open(path) as tar:
        return {t.name: Member(t.name, t.size, t.offset_data, t.isreg())
                for t in tar.getmembers()}


def _write(path: Path, entries: list[tuple[str, bytes | None]],
           pax: dict[str, dict[str, str]] | None = None) -> None:
    """A pax-format tar of ``entries`` (None: a folder), each with the extra pax
    records ``pax`` gives it."""
    with tarfile.open(path, "w", format=tarfile.PAX_FORMAT) as tar:
        for name, data in entries:
            info = tarfile.TarInfo(name)
            if data is None:
                info.type = tarfile.DIRTYPE
            else:
                info.size = len(data)
            info.pax_headers = dict((pax or {}).get(name, {}))
            tar.addfile(info, None if data is None else io.BytesIO(data))


def test_long_names_read_from_pax_records_as_tarfile_reads_them(tmp_path: Path) -> None:
    long_folder = "annotations/aps/" + "0x28" * 70  # 296 characters: no ustar header holds it
    entries = [("index.json", b"{}"), ("annotations", None), (long_folder, None),
               (long_folder + "/states/values.bin", bytes(range(200)) * 3),
               ("short.bin", b"x" * 513)]
    path = tmp_path / "long.umb"
    _write(path, entries)
    raw = path.read_bytes()
    assert b"path=" + long_folder.encode() in raw  # a pax record names it (the premise)
    found = prism_archive._read(str(path))  # no fallback to tarfile
    assert found == _tarfile_view(path)
    assert set(found) == {"index.json", "annotations", long_folder,
                          long_folder + "/states/values.bin", "short.bin"}
    member = found[long_folder + "/states/values.bin"]
    assert read_member(str(path), member) == bytes(range(200)) * 3  # the bytes written
    assert not found[long_folder].regular and found[long_folder].size == 0


def test_a_pax_key_not_read_here_goes_to_tarfile(tmp_path: Path) -> None:
    path = tmp_path / "comment.umb"
    _write(path, [("a" * 120 + ".bin", b"abc"), ("b.bin", b"defg")],
           pax={"b.bin": {"comment": "written by a test"}})
    with pytest.raises(prism_archive._Other):
        prism_archive._read(str(path))
    assert members(str(path)) == _tarfile_view(path)  # tarfile's answer
    assert read_member(str(path), members(str(path))["b.bin"]) == b"defg"


@pytest.mark.parametrize("records", [
    b"99 path=x\n",  # a length past the records
    b"12 pathx\n",  # no '='
    b"path=x\n",  # no length
])
def test_a_malformed_pax_record_is_refused(records: bytes) -> None:
    with pytest.raises(prism_archive._Other):
        prism_archive._pax(records)


def test_pax_records_by_key() -> None:
    text = b"30 path=annotations/aps/x/y\n" + b"9 size=7\n"
    assert len(b"30 path=annotations/aps/x/y\n") == 28  # (the length counts the record)
    with pytest.raises(prism_archive._Other):
        prism_archive._pax(text)  # 30 is not its length
    good = b"28 path=annotations/aps/x/y\n" + b"10 size=7\n"
    assert prism_archive._pax(good) == {"path": "annotations/aps/x/y", "size": "7"}


@needs_storm
def test_storms_export_with_a_long_label_is_read_without_tarfile(tmp_path: Path) -> None:
    import stormpy
    import stormpy.io

    name = "goal_" + "long" * 70  # 285 characters
    prism = tmp_path / "walk.prism"
    prism.write_text("mdp\nmodule m\n  x : [0..3] init 0;\n"
                     "  [go] x<3 -> 0.5 : (x'=x+1) + 0.5 : (x'=x);\n"
                     "  [stay] true -> (x'=x);\nendmodule\n"
                     f'label "{name}" = x=2;\n')
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    model = stormpy.build_model(stormpy.parse_prism_program(str(prism)), options=options)
    export = stormpy.io.UmbExportOptions()
    export.compression = stormpy.io.CompressionMode.NO_COMPRESSION
    path = tmp_path / "walk.umb"
    stormpy.io.export_to_umb(model, str(path), options=export)
    found = prism_archive._read(str(path))
    assert found == _tarfile_view(path)
    values = f"annotations/aps/{name}/states/values.bin"
    assert values in found and found[values].size > 0
