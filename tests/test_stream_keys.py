"""The fixed random streams of the acquisition's later steps (own streams, so that a step that replaces
nothing leaves every other draw as without it): their spawn keys under the estimate's seed are distinct and
beyond any count `Generator.spawn` / `SeedSequence.spawn` reaches in one estimate (a few dozen islands and
twins), so no two steps, and no island, share a stream."""

from __future__ import annotations

from photoservo.vision import candidates, estimator

SPAWNS = 1000  # far above the acquisition's spawns of one estimate


def test_the_steps_stream_keys_are_distinct_and_beyond_the_acquisitions_spawns():
    # first entries of spawn_key under SeedSequence(seed): the bridged islands' (the grown islands' the same
    # child, as the two never seed one acquisition), foam_turns' and parted_turns' plane step's
    roots = {"bridged": estimator.BRIDGED_STREAMS, "foam_turns": candidates.FOAM_TURN_STREAMS,
             "parted_plane": candidates.PARTED_PLANE_STREAMS}
    assert len(set(roots.values())) == len(roots), roots
    assert min(roots.values()) > SPAWNS
    assert estimator.GROWN_STREAMS not in (candidates.FOAM_TURN_STREAMS, candidates.PARTED_PLANE_STREAMS)
    assert estimator.GROWN_STREAMS > SPAWNS
    # layout_refit's: appended to an island's own key, beyond that island's spawns
    assert candidates.LAYOUT_STREAM > SPAWNS

