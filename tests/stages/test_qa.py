"""QA flags that `mpmfx status --qa` prints."""

from mpmfx.stages.qa import flags


def test_flags_mass_change_energy_jump_and_lost_particles():
    qa = {
        1: {"mass": 1.0, "kinetic_energy": 1.0, "max_speed": 1.0},
        2: {"mass": 1.0, "kinetic_energy": 2.0, "max_speed": 1.3},  # gravity can do this: not flagged
        3: {
            "mass": 0.99,
            "kinetic_energy": 6.0,
            "max_speed": 9.0,
            "j_min": -0.2,
            "particles_lost": 4,
            "rejected_substeps": 2,
        },
    }
    out = flags(qa, gravity=9.81, frame_dt=1 / 24)
    assert 1 not in out and 2 not in out
    text = "; ".join(out[3])
    assert "mass changed" in text and "energy x3.0 beyond what gravity explains" in text and "4 particles lost" in text
    assert "2 substeps rejected" in text and "inverted particles" in text
