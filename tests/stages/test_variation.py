"""Material variation through the pipeline: schema, keys and what it does to a snow block."""

from __future__ import annotations

import numpy as np
import pytest

import mpmfx
from mpmfx.config import ShotError
from mpmfx.io.frames import ParticleFrame
from mpmfx.shotfile import load_shot_config
from tests.conftest import write_tiny_shot

VARY = "objects.0.variation={{youngs_modulus = {a}, hardening = {a}, feature_size = 0.04, seed = 5}}"
DROP = ["objects.0.translate=[0.5, 0.3, 0.5]", "objects.0.velocity=[0.0, -3.0, 0.0]"]  # lands in frame 2


def _run(shot, cache, amplitude=None, sets=()):
    sets = [*sets] + ([] if amplitude is None else [VARY.format(a=amplitude)])
    results = mpmfx.load_shot(shot, overrides=sets, cache_root=cache, quiet=True).run(until="simulate")
    return {r.stage: r.entry for r in results}


def _frames(entry):
    return [ParticleFrame.read(f) for f in sorted((entry / "frames").glob("*.npz"))]


@pytest.fixture(scope="module")
def snow(tmp_path_factory):
    folder = tmp_path_factory.mktemp("vary")
    return write_tiny_shot(folder, material="Soft", frame_end=3), folder / "cache"


def test_zero_amplitudes_give_the_unvaried_frames_byte_for_byte(snow):
    shot, cache = snow
    plain, zero = _run(shot, cache, None, DROP), _run(shot, cache, 0.0, DROP)
    assert len(list((plain["simulate"] / "frames").glob("*.npz"))) == 3
    assert plain["voxelise"] == zero["voxelise"]  # variation is the simulate stage's: no re-voxelising
    assert plain["simulate"] != zero["simulate"]  # a varied solver is another entry...
    for a, b in zip(
        sorted((plain["simulate"] / "frames").glob("*.npz")), sorted((zero["simulate"] / "frames").glob("*.npz"))
    ):
        assert a.read_bytes() == b.read_bytes(), a.name  # ...with the same frames


def test_the_spread_of_plastic_compression_grows_with_the_amplitude(snow):
    """The block lands hard on the floor: uniform snow packs layer by layer (log Jp varies
    with height, little across a layer); varied snow packs where it is soft and less where it
    is stiff, so within a layer the spread of log Jp grows with the amplitude."""
    shot, cache = snow
    spread = []
    for a in (None, 0.3, 0.8):
        frames = _frames(_run(shot, cache, a, DROP)["simulate"])[:3]
        y0, log_jp = frames[0].x[:, 1], np.log(frames[-1].Jp)
        layer = np.digitize(y0, np.quantile(y0, np.linspace(0, 1, 13)[1:-1]))  # 12 layers by rest height
        spread.append((log_jp - np.array([log_jp[layer == k].mean() for k in range(12)])[layer]).std())
    assert spread[0] < spread[1] < spread[2], spread  # measured 0.018, 0.022, 0.032
    assert spread[2] > 1.5 * spread[0], spread


def test_bad_variation_is_refused_naming_file_and_key(snow, capsys):
    shot, cache = snow
    for bad, match in (
        (
            "{youngs_modulus = -0.1, feature_size = 0.1}",
            r"variation.youngs_modulus' = -0.1: .*greater than or equal to 0",
        ),
        ("{youngs_modulus = 0.1, feature_size = 0.0}", r"variation.feature_size' = 0.0: .*greater than 0"),
        ("{stifness = 0.1, feature_size = 0.1}", r"unknown key 'objects\[0\].variation.stifness'"),
        ("{friction_angle = 0.1, feature_size = 0.1}", r"variation.friction_angle: Soft is snow, which has no"),
    ):
        with pytest.raises(ShotError, match=rf"{shot.name}: .*{match}"):
            load_shot_config(shot, [f"objects.0.variation={bad}"])
    from mpmfx.cli import main

    args = ["run", str(shot), "--set", "objects.0.variation={density = 2.0, feature_size = 0.1}", "--cache", str(cache)]
    assert main(args) == 2
    assert "objects[0].variation.density" in capsys.readouterr().err


def test_a_varied_run_continues_from_its_checkpoint_byte_for_byte(snow, tmp_path):
    """A longer shot continues from the cached frames (the checkpoint carries the multipliers):
    its frames are those of one uninterrupted run."""
    shot, cache = snow
    _run(shot, cache, 0.3, DROP)  # (a cache hit after the test above)
    longer = [*DROP, "shot.frame_end=4"]
    continued, straight = _run(shot, cache, 0.3, longer), _run(shot, tmp_path, 0.3, longer)
    frames = [sorted((e["simulate"] / "frames").glob("*.npz")) for e in (continued, straight)]
    assert len(frames[0]) == len(frames[1]) == 4
    for a, b in zip(*frames):
        assert a.read_bytes() == b.read_bytes(), a.name


def test_an_emitter_varies_along_its_stream_not_puff_by_puff_the_same(tmp_path):
    """An emitter's particles sample the noise at their stream position (source position less
    velocity x birth): two puffs 0.1 s apart at 1 m/s, five feature sizes along the stream,
    are uncorrelated at the same source points; puffs 1 ms apart, 1/20 of a feature, nearly
    equal; and the object without variation stays uniform."""
    from mpmfx.stages.simulate import variation

    extra = (
        '\n[[emitters]]\nname = "hose"\nshape = "box"\nsize = [0.1, 0.1, 0.1]\ntranslate = [0.5, 0.7, 0.5]\n'
        'material = "Mushy"\nrate = 0.01\nvelocity = [0.0, -1.0, 0.0]\nend_time = 0.5\n'
        "variation = {youngs_modulus = 0.3, feature_size = 0.02, seed = 3}\n"
    )
    shot = load_shot_config(write_tiny_shot(tmp_path, material="Soft", frame_end=3, extra=extra))
    src = np.random.default_rng(0).uniform([0.45, 0.65, 0.45], [0.55, 0.75, 0.55], (2000, 3))
    x = np.concatenate([src, src, src, src])
    body = np.repeat([1, 1, 1, 0], len(src))  # three puffs of the emitter (body 1), then the object
    birth = np.repeat([0.2, 0.3, 0.201, 0.0], len(src))
    log_e = np.log(variation(shot, x, body, birth)[:, 0]).reshape(4, -1)
    assert log_e[0].std() == pytest.approx(0.3, rel=0.3)  # the amplitude
    assert abs(np.corrcoef(log_e[0], log_e[1])[0, 1]) < 0.2  # another puff, another part of the noise
    assert np.corrcoef(log_e[0], log_e[2])[0, 1] > 0.95  # a steady stream varies smoothly
    assert np.all(log_e[3] == 0.0)
