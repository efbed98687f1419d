"""What the terminal says where a new user stumbled (issue 32): a case that kept no tracer
says why and what to change."""

from rimcl.cli.stats import no_tracer_hint


def test_a_case_without_tracers_says_what_to_change():
    case = {
        "name": "C4",
        "n_tracers": 30,
        "n_used": 0,
        "n_excluded": {"split": 21, "below_threshold": 30, "no_rays": 0, "saturated": 3},
    }
    hint = no_tracer_hint(case)
    assert hint.strip().startswith("C4 kept no tracer, so its errors are n/a (30 below_threshold:")
    # the commonest cause first, each with the option or key to change; none for a cause
    # that excluded no tracer, or that has no remedy to name
    assert hint.index("below_threshold") < hint.index("21 split")
    assert "--threshold" in hint and "--fan" in hint and "no_rays" not in hint
    assert "saturated" not in hint
    assert no_tracer_hint({**case, "n_used": 1}) is None
    assert no_tracer_hint({**case, "n_tracers": 0}) is None
