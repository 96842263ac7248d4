"""The TUI on a real NIfTI CT: the export menu offers only what the input supports and says
why DICOM-SEG and RTSTRUCT are missing; default names come from the input's stem
(``ct_abdomen_3mm.nii.gz`` -> ``ct_abdomen_3mm-labels.nii.gz``, ``ct_abdomen_3mm.ctui``); a
pre-filled prompt says how to clear it."""

from __future__ import annotations

from support import shared

from ctui.engine.actions.formats import FORMATS
from ctui.screens.app import CtuiApp
from ctui.screens.testing import choose, wait_workspace


async def test_export_menu_and_default_names_on_a_nifti_ct(tmp_path):
    from textual.widgets import Input, Label, OptionList

    ct = shared("totalseg_example") / "ct_abdomen_3mm.nii.gz"
    app = CtuiApp(path=str(ct))
    async with app.run_test(size=(120, 40)) as pilot:
        await wait_workspace(pilot, app)
        s = app.session
        s.seg.paint(s.volume.data > 200, s.current)  # bone: something to export
        await pilot.press("e")
        await pilot.pause()
        ol = app.screen.query_one(OptionList)
        ids = [ol.get_option_at_index(i).id for i in range(ol.option_count)]
        assert "dicom-seg" not in ids and "rtstruct" not in ids
        assert [i for i in ids if i in FORMATS] == [f for f in FORMATS if FORMATS[f].needs != "dicom"]
        note = " ".join(str(lab.render()) for lab in app.screen.query(Label))
        assert "Not offered: DICOM-SEG, RTSTRUCT" in note and "NIfTI" in note
        await choose(pilot, "nifti")
        inp = app.screen.query_one(Input)
        assert inp.value.endswith("/ct_abdomen_3mm-labels.nii.gz"), inp.value
        hint = " ".join(str(lab.render()) for lab in app.screen.query(Label))
        assert "Ctrl+U clears it" in hint
        await pilot.press("escape")
        await pilot.pause()
        await pilot.press("ctrl+s")
        await pilot.pause()
        assert app.screen.query_one(Input).value.endswith("/ct_abdomen_3mm.ctui")
        await pilot.press("escape")
        await pilot.pause()
        assert not app.errors, app.errors
