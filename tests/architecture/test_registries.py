"""One registry per kind of choice: the CLI's choices and the TUI's menus and cycles are the
engine's registries (export formats, render modes, segmentation methods), a format added
to the registry shows up in ``ctui export --help`` and the TUI's export menu and is
written by the export action, outputs are named from the input's stem, and the export
menu offers only what the input supports, saying why the others are missing."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from ctui.cli import build_parser, main
from ctui.engine.actions import formats
from ctui.engine.actions.formats import FORMATS, ExportFormat, output_name, output_stem
from ctui.engine.core.errors import CtuiError
from ctui.engine.core.rendermodes import MODES
from ctui.engine.core.volume import Volume


def _choices(command: str, option: str) -> tuple:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    act = sub.choices[command]._option_string_actions[option]
    return tuple(act.choices)


def _session(fmt: str, source: str = "/data/ct.nii.gz"):
    from ctui.screens.session import Session

    data = np.zeros((6, 20, 22), np.int16)
    data[2:4, 5:12, 6:14] = 300
    vol = Volume(data, spacing=(3.0, 1.0, 1.0), modality="CT", window=(40.0, 400.0), meta={"format": fmt})
    s = Session(vol, source_path=source)
    s.seg.paint(data > 0, s.seg.add_object("kidney"))
    return s


def test_cli_choices_are_the_engine_registries():
    assert _choices("export", "--format") == tuple(FORMATS)
    assert _choices("render", "--mode") == MODES
    from ctui.engine.actions import batch
    from ctui.engine.segment.methods import METHODS

    assert _choices("segment", "--method") == tuple(METHODS) == _choices("drift", "--method")
    assert batch.METHODS is METHODS  # the manifest's method column
    from ctui.engine.actions import defaults
    from ctui.screens import view3d

    assert _choices("mesh", "--method") == defaults.MESH_METHODS == view3d.METHODS  # the 3D view's c cycle


def test_tui_menus_are_the_engine_registries():
    from ctui.screens import view3d
    from ctui.screens.export import CURRENT, IMAGE, menu_items

    items, note = menu_items(_session("dicom"))
    ids = [k for k, _ in items]
    assert [k for k in ids if k in FORMATS] == list(FORMATS) and note == ""
    assert [k for k in ids if k.endswith(CURRENT)] == [f.name + CURRENT for f in FORMATS.values() if f.per_object]
    assert ids[-1] == IMAGE[0]

    class Stub:  # the 3D view's `m` cycle, without a screen
        mode = MODES[0]

        def _info(self):
            pass

        def request_render(self):
            pass

    stub, seen = Stub(), []
    for _ in MODES:
        view3d.View3DScreen.action_mode(stub)
        seen.append(stub.mode)
    assert sorted(seen) == sorted(MODES) and "minip" in seen


def test_export_menu_offers_what_the_input_supports():
    from ctui.screens.export import menu_items

    items, note = menu_items(_session("nifti"))
    ids = {k for k, _ in items}
    assert "dicom-seg" not in ids and "rtstruct" not in ids and {"nifti", "nrrd", "stl", "csv", "mric"} <= ids
    assert "DICOM-SEG, RTSTRUCT" in note and "NIfTI" in note and "needs the DICOM series" in note
    # the engine refuses the same export with the same reason, naming its keyword (the CLI adds the flag)
    from ctui.screens.export import export_session

    with pytest.raises(CtuiError, match="needs the DICOM series") as err:
        export_session(_session("nifti"), "dicom-seg", "/tmp/never-written.dcm")
    assert err.value.option == "series"


def test_a_registered_format_reaches_the_cli_help_the_tui_menu_and_the_action(tmp_path, capsys):
    from ctui.screens.export import default_name, export_session, menu_items

    def write_tiny(job):  # one line per object: "id name voxels"
        lines = [f"{o['id']} {o['name']} {int((job.labels == o['id']).sum())}" for o in job.objs]
        job.path.write_text("\n".join(lines) + "\n")

    formats.register(ExportFormat("tiny", "Tiny: object sizes as text", (".tiny",), write_tiny, tag="sizes"))
    try:
        with pytest.raises(SystemExit):
            main(["export", "--help"])
        assert "tiny" in capsys.readouterr().out
        s = _session("nifti")
        items, _ = menu_items(s)
        assert ("tiny", "Tiny: object sizes as text") in items
        assert default_name(s, "tiny").endswith("/ct-sizes.tiny")
        out = tmp_path / "k.tiny"
        res = export_session(s, "tiny", str(out))
        assert out.read_text() == f"1 kidney {2 * 7 * 8}\n" and res.format == "tiny"
        with pytest.raises(CtuiError, match=r"ends in \.tiny"):
            export_session(s, "tiny", str(tmp_path / "k.txt"))
    finally:
        formats.unregister("tiny")
    assert "tiny" not in _choices("export", "--format")


@pytest.mark.parametrize("source, suffix, tag, name", [
    ("/d/ct.nii.gz", ".ctui", "", "ct.ctui"),
    ("/d/ct.nii.gz", ".nii.gz", "labels", "ct-labels.nii.gz"),
    ("/d/scan 1/", ".ctui", "", "scan_1.ctui"),
    ("/d/kidney.ctui", ".stl", "objects", "kidney-objects.stl"),
    ("/d/seg.seg.nrrd", ".csv", "measurements", "seg-measurements.csv"),
    ("", ".ctui", "", "ctui.ctui"),
])
def test_outputs_are_named_from_the_input_stem(source, suffix, tag, name):
    assert output_name(source, suffix, tag=tag) == name
    assert "." not in output_stem(source)


def test_tui_default_export_names():
    from ctui.screens.export import default_name

    s = _session("nifti", "/data/ct_abdomen_3mm.nii.gz")
    assert default_name(s, "nifti").endswith("/ct_abdomen_3mm-labels.nii.gz")
    assert default_name(s, "stl:current").endswith(f"/ct_abdomen_3mm-object{s.current}.stl")
    assert default_name(s, "image").endswith(f"/ct_abdomen_3mm-slice{s.z}.png")


def test_projects_from_every_face_have_one_propagation_shape(tmp_path):
    """The TUI's project and ctui segment's carry the propagation through one function;
    the TUI's save refuses the series folder as the CLI does."""
    from ctui.engine.actions.project import propagation_record, save_project
    from ctui.engine.io.projectschema import PROPAGATION_KEYS
    from ctui.screens.projects import project_from_session

    series = tmp_path / "series"
    series.mkdir()
    s = _session("nifti", str(series))
    prop = project_from_session(s).propagation
    assert set(prop) <= set(PROPAGATION_KEYS) and prop["current"] == s.current and prop["connectivity"] == 8
    two = propagation_record([{"low": 1, "high": 2}, {"low": 3, "high": 4}], current=2)
    assert two["low"] == 1 and [p["low"] for p in two["per_object"]] == [1, 3] and two["current"] == 2
    with pytest.raises(CtuiError, match="inside the input folder"):
        save_project(series / "work.ctui", project_from_session(s))


def test_drift_labels_must_match_the_series_geometry(tmp_path, sample_dir, capsys):
    """ctui drift SERIES --labels FILE: a label file of the same shape on another grid is refused."""
    from ctui.engine.io.labels import save_labels
    from ctui.engine.io.series import load

    series = sample_dir / "phantom"
    vol = load(series)
    labels = np.zeros(vol.shape, np.uint8)
    labels[vol.shape[0] // 3: 2 * vol.shape[0] // 3, 10:20, 10:20] = 1
    other = Volume(labels, spacing=tuple(np.multiply(vol.spacing, (1, 2, 2))), origin=vol.origin,
                   direction=vol.direction)  # the same shape, twice the pixel size
    save_labels(tmp_path / "other.nii.gz", labels, other)
    assert main(["drift", str(series), "--labels", str(tmp_path / "other.nii.gz")]) == 2
    err = capsys.readouterr().err
    assert "other.nii.gz" in err and "voxel size" in err, err
    save_labels(tmp_path / "same.nii.gz", labels, vol)
    assert main(["drift", str(series), "--labels", str(tmp_path / "same.nii.gz")]) == 0


def test_side_panel_shows_long_object_names_in_full():
    """An object's name is not cut to 10 characters: a long one gets a line of its own."""
    from ctui.screens.ws_keys import panel_text
    from ctui.screens.ws_state import EditTools, ObjectVolumes, ProposalState, SeedRange, ViewState

    s = _session("nifti")
    s.seg.objects[1].name = "kidney_left_lower_pole"
    s.seg.add_object("liver")

    class Ws:  # what panel_text reads of the workspace
        def __init__(self, session):
            self.s = session
            self.viewstate = ViewState()
            self.volumes = ObjectVolumes()
            self.edit_tools = EditTools()
            self.pending = ProposalState()
            self.seed_range = SeedRange()
            self.size = type("Size", (), {"width": 120, "height": 40})()

        def call_after_refresh(self, *_a) -> None:  # the seed range waits for a painted screen: none here
            pass

        def update_panel(self) -> None:
            pass

    text = panel_text(Ws(s)).plain
    assert "kidney_left_lower_pole" in text and " liver " in text
    row = next(line for line in text.splitlines() if "kidney_left_lower_pole" in line)
    assert len(row) <= 36 and "ml" in text.splitlines()[text.splitlines().index(row) + 1]


def test_cli_help_names_the_registries_it_cannot_import():
    """``ctui --help`` may not import numpy, so the filter and DVR-preset names in the CLI's
    help are text: they must be the engine's registries, all of them."""
    import re

    from ctui.commands.segment import FILTER_HELP
    from ctui.engine.render.transfer import PRESETS
    from ctui.engine.segment.filters import FILTERS

    named = re.search(r"Names: ([a-z ]+)\.", FILTER_HELP).group(1).split()
    assert sorted(named) == sorted(FILTERS)
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    preset_help = sub.choices["render"]._option_string_actions["--preset"].help
    assert set(re.findall(r"(?:ct|mr)-[a-z-]+", preset_help)) == set(PRESETS)


async def test_a_registered_segmentation_method_reaches_the_cli_the_tui_panel_and_the_action(capsys):
    """One function and one register() call: ``ctui segment --method`` accepts and lists it,
    the TUI's segmentation panel offers it, and the segment action runs it."""
    from textual.app import App
    from textual.widgets import Select

    from ctui.engine.actions.segment import SegmentOptions, segment
    from ctui.engine.segment import methods
    from ctui.screens.segpanel import SegmentPanel

    def seed_slice_only(job):  # the seed slice's object, not propagated
        mask = np.zeros(job.seg.labels.shape, bool)
        mask[job.seed[2]] = job.start
        job.seg.paint(mask, job.oid)

    methods.register("seedslice", seed_slice_only, "the seed slice's object only (a test method)")
    try:
        assert "seedslice" in _choices("segment", "--method")
        with pytest.raises(SystemExit):
            main(["segment", "--help"])
        assert "seedslice: the seed slice's object only" in " ".join(capsys.readouterr().out.split())
        s = _session("nifti")
        res = segment(s.volume, [(8, 7, 2)], [(200.0, 400.0)], options=SegmentOptions(method="seedslice"))
        lab = res.segmentation.labels
        assert (lab[2] == 1).sum() == 7 * 8 and not lab[3].any()  # the block is on slices 2-3: only 2 taken

        class Host(App):
            def on_mount(self) -> None:
                self.push_screen(SegmentPanel(s))

        async with Host().run_test() as pilot:
            await pilot.pause()
            offered = [v for _, v in pilot.app.screen.query_one("#method", Select)._options]
        assert offered == list(methods.METHODS)
    finally:
        methods.METHODS.pop("seedslice", None)


def test_tui_outputs_refuse_the_source_folder(tmp_path):
    """The slice-view PNG (the one TUI export not written by actions.export) passes the same
    output check as every other export: never inside the series folder."""
    from ctui.screens.export import run_export

    series = tmp_path / "series"
    series.mkdir()

    class Ws:
        s = _session("dicom", str(series))
        main_view = None  # never reached: the check comes first

    with pytest.raises(CtuiError, match="inside the input folder"):
        run_export(Ws(), "image", str(series / "slice.png"))
    with pytest.raises(CtuiError, match="inside the input folder"):
        run_export(Ws(), "nifti", str(series / "labels.nii.gz"))
    assert list(series.iterdir()) == []
