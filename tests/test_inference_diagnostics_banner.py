"""The app's convergence banner (diagnostics.banner_status) and the parameter glossary."""
from lvcore.inference.diagnostics import Convergence, banner_status
from lvcore.inference.models import PARAMETER_HELP


def _conv(**kw):
    base = {"converged": True, "max_rhat": 1.004, "min_ess_bulk": 900.0, "min_ess_tail": 800.0, "n_divergent": 0,
            "failing": ()}
    return Convergence(**{**base, **kw})


def test_green_only_when_clean():
    level, text = banner_status(_conv())
    assert level == "success"
    assert "divergences 0" in text and "R-hat 1.004" in text and "ESS 900" in text


def test_divergences_make_it_amber_even_when_converged():
    level, text = banner_status(_conv(n_divergent=11))
    assert level == "warning" and "11 divergent" in text


def test_low_ess_makes_it_amber_even_when_the_check_passed():
    level, text = banner_status(_conv(min_ess_bulk=250.0))  # above the check's 100, below the banner's 400
    assert level == "warning" and "250 < 400" in text


def test_not_converged_is_amber_and_names_the_parameters():
    level, text = banner_status(_conv(converged=False, max_rhat=1.2, failing=("a", "bf")))
    assert level == "warning" and "a, bf" in text


def test_every_reported_parameter_is_explained():
    for n in ("a", "b", "af", "bf", "sigma_s_sq", "sigma_s2", "v", "lam", "sigma1_sq", "sigma2_sq", "c", "tau"):
        assert PARAMETER_HELP[n].strip()


def test_banner_lists_the_verdicts_flags():
    """A converged run whose posterior piles on a prior bound is amber, with the flag in the text (issue 27)."""
    from lvcore.inference.diagnostics import Convergence, banner_status

    conv = Convergence(True, 1.001, 2000.0, 2000.0, 0, ())
    assert banner_status(conv)[0] == "success"
    level, text = banner_status(conv, flags=["IDENTIFIABILITY: a: posterior piled on the prior's lower bound 0.05"])
    assert level == "warning" and "flagged (1): IDENTIFIABILITY: a: posterior piled" in text and "lower bound 0.05" in text
    assert "CLI" not in text and "exit code" not in text  # the app's own words


def test_each_flag_once_the_sampler_flags_are_the_banners_own_findings():
    """The verdict's SAMPLER flags restate the banner's convergence and divergence findings: the banner says each
    once (a single chain: R-hat n/a, not nan)."""
    from lvcore.inference import verdict

    conv = _conv(converged=False, max_rhat=float("nan"), failing=("a", "R-hat needs >= 2 chains"), n_divergent=30)
    flags = ["BOUND: af: posterior piled on the prior's lower bound 0.05"]
    flags += [f"SAMPLER: {f}" for f in verdict.sampler_flags(conv, 100)]
    assert len(flags) == 3
    level, text = banner_status(conv, flags=flags)
    assert level == "warning" and text.count("not converged") == 1 and text.count("divergent") == 1
    assert "30 divergent transitions in 100 draws" in text and "flagged (3): BOUND: af" in text
    assert "SAMPLER (the sampler problems above)" in text and "NOT CONVERGED" not in text
    assert "nan" not in text and "max R-hat n/a (needs ≥ 2 chains)" in text
