"""The camera twin's sensor config from the camera node's params: the realism's preset, each set param over
it."""

from __future__ import annotations

from types import SimpleNamespace

from flexsheet.model.truth_choice import TruthChoice
from flexsheet.twin.camera_config import SimConfig
from flexsheet.twin.camera_source import sim_config


def _params(realism: str, **set_) -> SimpleNamespace:
    unset = dict.fromkeys(("noise_dn", "shot_gain", "blur_px", "self_occlusion", "background_gain",
                           "finger_dir"))
    return SimpleNamespace(twin=TruthChoice(realism=realism), exposure_s=0.004, blur_samples=5, clutter=False,
                           seed=0, noise_scale=1.0, **{**unset, **set_})


def test_the_realism_presets_and_a_set_param_overrides_its_preset():
    real, ideal = sim_config(_params("realistic")), sim_config(_params("ideal"))
    assert real.noise_dn == SimConfig().noise_dn and ideal.noise_dn == SimConfig.ideal().noise_dn
    assert real.noise_dn != ideal.noise_dn
    both = sim_config(_params("ideal", noise_dn=3.5))
    assert both.noise_dn == 3.5 and both.blur_px == SimConfig.ideal().blur_px and both.exposure_s == 0.004
