"""An effect is one module plus its kernel arithmetic: no other product file names its
config fields (``python -m studies.effect_cost``).

The effects that landed through ``servo/physics/`` (dead zone, cubic spring, backlash,
drift) are named by no file outside their module, the registry, ``kernels/`` and
``firmware/``.  The effects older than the registry are still named elsewhere (the
identification of eq. 3, the paper's experiments, the HDD benchmark's drives, the
diagnosis's stages): :data:`LEGACY` lists those files as of this test, and a file not
listed that names one fails, so the list only shrinks.
"""
from __future__ import annotations

import pytest

from servo import physics
from studies.effect_cost import c_names, cost, python_names

LEGACY = {
    "inertia": ("servo/compensate/check.py", "servo/compensate/job.py", "servo/compensate/model.py",
        "servo/compensate/plausible.py", "servo/config.py", "servo/design/track_following.py",
        "servo/diagnose/concealed.py", "servo/diagnose/fit.py", "servo/diagnose/frf_modes.py",
        "servo/diagnose/simulate.py", "servo/experiments/bode_analysis.py", "servo/experiments/cancel.py",
        "servo/experiments/hysteresis.py", "servo/experiments/square_wave.py", "servo/fleet/identify.py",
        "servo/fleet/synthetic.py", "servo/hdd/designs.py", "servo/hdd/drive.py", "servo/identify/identification.py",
        "servo/identify/job.py", "servo/identify/least_squares.py", "servo/identify/plots.py",
        "servo/identify/regressors.py", "servo/loop/design.py", "servo/physics/backlash.py",
        "servo/runtime/simplant.py",),
    "viscous_friction": ("servo/compensate/model.py", "servo/design/loop.py", "servo/diagnose/concealed.py",
        "servo/diagnose/frf_modes.py", "servo/experiments/bode_analysis.py", "servo/experiments/square_wave.py",
        "servo/fleet/identify.py", "servo/fleet/synthetic.py", "servo/hdd/drive.py", "servo/identify/regressors.py",
        "servo/io/runlog.py", "servo/loop/design.py", "servo/lti.py", "servo/physics/asymmetric.py",),
    "coulomb_friction": ("servo/compensate/model.py", "servo/config.py", "servo/diagnose/breakaway.py",
        "servo/diagnose/concealed.py", "servo/diagnose/job.py", "servo/experiments/cancel.py",
        "servo/experiments/hysteresis.py", "servo/experiments/hysteresis_plots.py",
        "servo/experiments/hysteresis_report.py", "servo/experiments/paper.py", "servo/experiments/square_wave.py",
        "servo/fleet/identify.py", "servo/fleet/synthetic.py", "servo/hdd/drive.py",
        "servo/identify/least_squares.py", "servo/identify/regressors.py", "servo/physics/hysteresis.py",
        "servo/physics/stribeck.py",),
    "stiffness": ("servo/cli/paper.py", "servo/compensate/model.py", "servo/config.py",
        "servo/diagnose/concealed.py", "servo/diagnose/frf_modes.py", "servo/diagnose/partial.py",
        "servo/diagnose/select.py", "servo/experiments/bode_analysis.py", "servo/experiments/hysteresis.py",
        "servo/experiments/hysteresis_plots.py", "servo/experiments/hysteresis_report.py",
        "servo/experiments/paper.py", "servo/experiments/square_wave.py", "servo/fleet/identify.py",
        "servo/fleet/synthetic.py", "servo/frf/estimate.py", "servo/hdd/drive.py", "servo/identify/least_squares.py",
        "servo/identify/regressors.py", "servo/loop/design.py", "servo/lti.py",),
    "offset": ("servo/compensate/model.py", "servo/diagnose/concealed.py", "servo/experiments/bode_analysis.py",
        "servo/experiments/hysteresis.py", "servo/experiments/hysteresis_plots.py",
        "servo/experiments/hysteresis_report.py", "servo/experiments/paper.py", "servo/experiments/square_wave.py",
        "servo/fleet/identify.py", "servo/fleet/synthetic.py", "servo/hdd/drive.py", "servo/identify/regressors.py",
        "servo/physics/drift.py", "servo/physics/hysteresis.py",),
    "asymmetric_friction": ("servo/compensate/residual.py", "servo/experiments/cancel.py",
        "servo/physics/coulomb.py",),
    "stribeck_friction": ("servo/compensate/model.py", "servo/compensate/residual.py", "servo/config.py",
        "servo/diagnose/breakaway.py", "servo/diagnose/concealed.py", "servo/diagnose/job.py",
        "servo/diagnose/report.py", "servo/experiments/cancel.py", "servo/fleet/synthetic.py", "servo/hdd/drive.py",
        "servo/physics/coulomb.py", "servo/physics/hysteresis.py",),
    "hysteresis": ("servo/cli/diagnose.py", "servo/cli/fleet.py", "servo/cli/paper.py", "servo/compensate/model.py",
        "servo/compensate/propose.py", "servo/compensate/significance.py", "servo/config.py",
        "servo/diagnose/breakaway.py", "servo/diagnose/concealed.py", "servo/diagnose/job.py",
        "servo/diagnose/report.py", "servo/diagnose/select.py", "servo/experiments/bode_analysis.py",
        "servo/experiments/cancel.py", "servo/experiments/hysteresis_plots.py",
        "servo/experiments/hysteresis_report.py", "servo/experiments/paper.py", "servo/experiments/square_wave.py",
        "servo/fleet/diagnose.py", "servo/hdd/drive.py", "servo/identify/dahl_fit.py", "servo/loop/design.py",),
    "resonance": ("servo/cli/identify.py", "servo/compensate/residual.py", "servo/config.py",
        "servo/diagnose/concealed.py", "servo/diagnose/simulate.py", "servo/experiments/bode_analysis.py",
        "servo/experiments/paper.py", "servo/hdd/benchmark.py", "servo/hdd/drive.py", "servo/loop/design.py",
        "servo/lti.py", "servo/runtime/simplant.py",),
    "time_delay": ("servo/diagnose/concealed.py", "servo/experiments/bode_analysis.py",
        "servo/experiments/square_wave.py", "servo/hdd/drive.py", "servo/loop/design.py", "servo/lti.py",
        "servo/runtime/simplant.py",),
    "input_saturation": ("hil/board.py", "hil/protocol.py", "hil/serialdriver.py", "servo/cli/bode.py",
        "servo/compensate/plausible.py", "servo/compensate/propose.py", "servo/controllers/base.py",
        "servo/diagnose/concealed.py", "servo/loop/measure.py", "servo/runtime/controller.py",
        "servo/runtime/simdriver.py", "servo/runtime/simplant.py", "servo/runtime/watchdog.py",),
    "position_dependent_gain": ("servo/compensate/job.py", "servo/compensate/propose.py",
        "servo/compensate/residual.py", "servo/experiments/cancel.py", "servo/hdd/drive.py",),
    "cogging": ("servo/compensate/residual.py", "servo/config.py", "servo/diagnose/terms.py",
        "servo/experiments/cancel.py", "servo/hdd/drive.py",),
    "quantization": ("servo/config.py", "servo/diagnose/concealed.py", "servo/hdd/drive.py",),
    "sensor_lag": ("servo/diagnose/concealed.py",),
    "hard_stops": ("servo/cli/hysteresis.py", "servo/compensate/model.py", "servo/compensate/plausible.py",
        "servo/compensate/propose.py", "servo/config.py", "servo/diagnose/concealed.py", "servo/loop/measure.py",
        "servo/physics/position_gain.py", "servo/runtime/watchdog.py",),
    "sensor_noise": ("hil/board.py", "hil/firmware.py", "servo/controllers/pi.py", "servo/diagnose/concealed.py",
        "servo/experiments/square_wave.py", "servo/hdd/drive.py", "servo/loop/design.py", "servo/loop/measure.py",
        "servo/runtime/simdriver.py",),
}  # fmt: skip


@pytest.fixture(scope="module")
def costs():
    return cost()


def test_the_scanner_sees_a_field_as_attribute_string_or_keyword_and_not_in_prose():
    src = '''"""The cubic spring k3 of the drive."""
# d.k3 in a comment
a = d.k3
b = f.get("k3")
c = f"{g('k3'):.3g}"
e = DriveConfig(k3=1.0)
k3 = 2.0
ax.plot(x, alpha=0.5)
'''
    assert python_names(src, {"k3", "alpha", "dead_zone"}) == {"k3"}
    assert python_names('"""k3"""\n# "k3"\n', {"k3"}) == set()
    assert python_names("x = d.dead_zone\n", {"k3", "dead_zone"}) == {"dead_zone"}
    assert c_names("f -= p->k3 * x;\n", {"k3", "dz_width"}) == {"k3"}
    assert c_names("double dz_width;\n", {"k3", "dz_width"}) == {"dz_width"}


def test_no_file_outside_an_effects_module_names_its_config_fields(costs):
    new = {}
    for name, c in costs.items():
        extra = set(c.outside) - set(LEGACY.get(name, ()))
        if extra:
            new[name] = {p: c.outside[p] for p in sorted(extra)}
    assert not new, f"files that name an effect's config fields outside its module (use its hooks): {new}"


def test_the_effects_of_the_new_home_cost_their_module_kernel_and_registration(costs):
    for name in ("dead_zone", "cubic_spring", "backlash", "drift"):
        c = costs[name]
        assert c.outside == {}, (name, c.outside)
        assert all(p.startswith(("kernels/", "firmware/")) for p in c.kernel + c.generated), c
        assert c.files == 2 + len(c.kernel) + len(c.generated)
    assert costs["dead_zone"].generated == ["firmware/records.h"]


def test_every_effect_is_counted_and_the_legacy_list_names_effects_that_exist(costs):
    assert list(costs) == list(physics.EFFECTS)
    assert set(LEGACY) <= set(physics.EFFECTS)


def test_adding_an_effect_is_the_eight_files_docs_model_md_lists(costs):
    """docs/model.md, "Adding an effect": the module, its MODULES line, kernels/plant.py,
    stage.py and cancel.py (whose functions take the fields as arguments, so the scan of
    record fields does not see it), the C mirror and the generated records: 8 files for
    the dead zone and the cubic spring."""
    from pathlib import Path

    cancel = (Path(__file__).resolve().parents[1] / "kernels" / "cancel.py").read_text()
    for name, fn in (("dead_zone", "def dead_zone_inverse("), ("cubic_spring", "def cubic_spring(")):
        c = costs[name]
        assert c.kernel == ["firmware/controller.c", "firmware/plant.c", "kernels/plant.py", "kernels/stage.py"], c
        assert c.generated == ["firmware/records.h"] and c.outside == {} and fn in cancel
        assert c.files + 1 == 8
