import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from dgpt_gym import make_tracker, tracker_ids
from dgpt_gym.benchmark.protocol import (
    PAPER_AS_PRINTED_TRACKERS,
    PAPER_GP_TRACKERS,
    WINDOWED_TRACKERS,
)
from dgpt_gym.naming import MODEL_SUFFIXES, PAPER_SUFFIX, TREND_SUFFIX, split_tracker_id, tracker_id


@given(
    approach=st.sampled_from(["gp", "dgpt-rbcm", "dgpt-gpoe", "dgpt-poe", "my-tracker"]),
    inputs=st.sampled_from(["tgp", "stgp"]),
    suffix=st.sampled_from(MODEL_SUFFIXES),
)
def test_split_inverts_tracker_id(approach, inputs, suffix):
    assert split_tracker_id(tracker_id(approach, inputs, suffix)) == (approach, inputs, suffix)


def test_examples_and_errors():
    assert tracker_id("dgpt-rbcm", "stgp", PAPER_SUFFIX) == "dgpt-rbcm-stgp-paper"
    assert tracker_id("gp", "stgp", TREND_SUFFIX) == "gp-stgp-trend"
    assert split_tracker_id("imm-pda") == ("imm-pda", "tgp", "")
    assert split_tracker_id("dgpt-bcm-silence") == ("dgpt-bcm-silence", "tgp", "")
    with pytest.raises(ValueError, match="inputs"):
        tracker_id("gp", "space")
    with pytest.raises(ValueError, match="suffix"):
        tracker_id("gp", "tgp", "-ncv")


def test_the_paper_sets_are_registered():
    registered = set(tracker_ids())
    assert set(PAPER_GP_TRACKERS + PAPER_AS_PRINTED_TRACKERS) <= registered
    assert PAPER_GP_TRACKERS[:3] == ("gp", "dgpt-rbcm", "dgpt-gpoe")
    assert len(PAPER_GP_TRACKERS) == 9 and "dgpt-gpoe-stgp-trend" in PAPER_GP_TRACKERS
    assert not set(WINDOWED_TRACKERS) & {"gp", "dgpt-rbcm", "dgpt-gpoe"}


@pytest.mark.parametrize(
    "old, new",
    [
        ("dgpt-bcm-ncv", "dgpt-bcm"),
        ("gp-stgp", "gp-stgp-trend"),
        ("hybrid-ncv", "hybrid"),
        ("dgpt-bcm-silence", "dgpt-bcm"),
    ],
)
def test_a_renamed_id_says_its_new_name(old, new):
    pattern = rf"renamed or retired: use {re.escape(new)}(\s|$)"
    with pytest.raises(ValueError, match=pattern):
        make_tracker(old)
