"""The how-to pages on reading rimcl's PIV vectors with OpenPIV and as PIVlab's MAT export run
as written (on 128 px frames: the pages' ``append`` directives)."""

import pytest
from doc_pages import DOCS, run_page


@pytest.mark.parametrize("page", ["openpiv.md", "pivlab.md"])
def test_the_howto_runs(page, tmp_path):
    assert run_page(DOCS / "howto" / page, tmp_path) >= 2
