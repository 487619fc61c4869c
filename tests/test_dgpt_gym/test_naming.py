import pytest
from hypothesis import given
from hypothesis import strategies as st

from dgpt_gym import tracker_ids
from dgpt_gym.benchmark.protocol import PAPER_AS_PRINTED_TRACKERS, PAPER_GP_TRACKERS
from dgpt_gym.naming import PAPER_SUFFIX, split_tracker_id, tracker_id


@given(
    approach=st.sampled_from(["gp", "dgpt-rbcm", "dgpt-gpoe", "dgpt-poe", "my-tracker"]),
    inputs=st.sampled_from(["tgp", "stgp"]),
    suffix=st.sampled_from(["", PAPER_SUFFIX]),
)
def test_split_inverts_tracker_id(approach, inputs, suffix):
    assert split_tracker_id(tracker_id(approach, inputs, suffix)) == (approach, inputs, suffix)


def test_examples_and_errors():
    assert tracker_id("dgpt-rbcm", "stgp", PAPER_SUFFIX) == "dgpt-rbcm-stgp-paper"
    assert split_tracker_id("imm-pda") == ("imm-pda", "tgp", "")
    with pytest.raises(ValueError, match="inputs"):
        tracker_id("gp", "space")


def test_the_paper_sets_are_registered():
    registered = set(tracker_ids())
    assert set(PAPER_GP_TRACKERS + PAPER_AS_PRINTED_TRACKERS) <= registered
    assert len(PAPER_GP_TRACKERS) == 6 and "dgpt-gpoe-stgp" in PAPER_GP_TRACKERS
