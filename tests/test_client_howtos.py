"""The how-to pages on reading rimcl's data with other tools run as written: OpenPIV's text
file and PIVlab's MAT export (on 128 px frames: the pages' ``append`` directives) and the LPT
challenge's layout (a 20-tracer, two-camera dataset). Each page renders its own data: 8-14 s
on 2 shared cores, most of it fixed start-up of the commands."""

import pytest
from doc_pages import DOCS, run_page


@pytest.mark.slow
@pytest.mark.parametrize("page", ["openpiv.md", "pivlab.md", "lpt-challenge.md"])
def test_the_howto_runs(page, tmp_path):
    assert run_page(DOCS / "howto" / page, tmp_path) >= 2
