"""The decoder's fast paths reject exactly what the plain checks reject.

Finite checks use one dot product per float column (or per pair of columns), which is exact when
it is finite and falls back to the elementwise check otherwise (overflow); array headers are looked
up in a cache of layouts that passed the full checks; the encoder caches array headers.
"""

from __future__ import annotations

import contextlib
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from wire_helpers import N_ACTIONS, small_transitions

from protocols.arrays import pack_array, unpack_array
from protocols.checks import BodyReader, all_finite, quiet_float_errors
from protocols.codec import decode, encode
from protocols.errors import ProtocolError
from protocols.limits import Limits
from protocols.messages import TransitionBatch, WeightsUpdate

LIMITS = Limits(n_actions=N_ACTIONS)
N, DIM = 1024, 11  # the benchmark's batch: longer than any SIMD block, with a ragged tail
BAD_VALUES = (np.nan, np.inf, -np.inf)
POSITIONS = (0, 1, 7, 8, 15, 16, 31, 5000, N * DIM - 9, N * DIM - 1)


def batch(**overrides):
    rng = np.random.default_rng(1)
    fields = dict(
        env_ids=np.arange(N) % 64,
        obs=rng.random((N, DIM), dtype=np.float32),
        action=rng.integers(0, N_ACTIONS, N),
        reward=rng.standard_normal(N).astype(np.float32),
        next_obs=rng.random((N, DIM), dtype=np.float32),
        terminated=rng.random(N) < 0.1,
        truncated=rng.random(N) < 0.1,
    )
    fields.update(overrides)
    return small_transitions(n=N, dim=DIM, **fields)


def rejection(message) -> ProtocolError:
    with pytest.raises(ProtocolError) as err:
        decode(encode(message), LIMITS)
    return err.value


@pytest.mark.parametrize("field", ["obs", "next_obs", "reward"])
@pytest.mark.parametrize("bad", BAD_VALUES)
def test_one_nonfinite_value_anywhere_is_rejected(field: str, bad: float) -> None:
    clean = batch()
    for position in POSITIONS:
        values = getattr(clean, field).copy()
        if position >= values.size:
            continue
        values.reshape(-1)[position] = bad
        err = rejection(batch(**{field: values}))
        assert err.reason == "nonfinite" and f"transitions.{field} holds 1 NaN" in err.message


def test_nonfinite_values_that_would_cancel_or_meet_zeros_are_rejected() -> None:
    obs, next_obs = np.zeros((N, DIM), np.float32), np.zeros((N, DIM), np.float32)
    obs[3, 4] = np.inf  # inf * 0 in the paired dot product
    assert rejection(batch(obs=obs, next_obs=next_obs)).reason == "nonfinite"
    obs, next_obs = np.ones((N, DIM), np.float32), np.ones((N, DIM), np.float32)
    obs[0, 0], obs[9, 1] = np.inf, -np.inf  # inf + (-inf) in the sum
    assert rejection(batch(obs=obs, next_obs=next_obs)).reason == "nonfinite"
    next_obs = np.ones((N, DIM), np.float32)
    next_obs[5, 5] = np.nan
    assert "next_obs holds 1 NaN" in rejection(batch(next_obs=next_obs)).message


def test_finite_values_whose_dot_product_overflows_still_decode() -> None:
    big = np.float32(3e38)  # finite, but big * big and any sum of them overflow float32
    obs = np.full((N, DIM), big, np.float32)
    reward = np.full(N, -big, np.float32)
    message = batch(obs=obs, next_obs=-obs, reward=reward)
    decoded = decode(encode(message), LIMITS)
    assert np.array_equal(decoded.obs, obs) and np.array_equal(decoded.reward, reward)
    tensors = {"w": np.full((64, 64), 1e300), "h": np.full(8, 6e4, np.float16)}
    weights = decode(encode(WeightsUpdate(model="m", version=1, tensors=tensors)), LIMITS)
    assert np.array_equal(weights.tensors["w"], tensors["w"])
    assert np.array_equal(weights.tensors["h"], tensors["h"])


@settings(max_examples=200, deadline=None)
@given(
    values=hnp.arrays(
        st.sampled_from([np.float16, np.float32, np.float64]),
        hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=40),
        elements={"allow_nan": True, "allow_infinity": True, "allow_subnormal": True},
    ),
    paired=st.booleans(),
)
def test_all_finite_equals_the_elementwise_check(values: np.ndarray, paired: bool) -> None:
    with quiet_float_errors():
        if paired:
            other = np.flip(values).copy()
            expected = bool(np.isfinite(values).all() and np.isfinite(other).all())
            assert all_finite(values, other) is expected
        else:
            assert all_finite(values) is bool(np.isfinite(values).all())


def test_decoding_hostile_floats_warns_about_nothing() -> None:
    obs = np.full((N, DIM), 3e38, np.float32)  # overflows the fast path's dot product
    obs[0, 0] = np.inf  # and inf * x, inf - inf on the way
    obs[1, 1] = -np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert rejection(batch(obs=obs, next_obs=obs)).reason == "nonfinite"
        decode(encode(batch(reward=np.full(N, 3e38, np.float32))), LIMITS)


def test_cached_array_layouts_still_check_the_data() -> None:
    flags = pack_array(np.array([True, False, True])).data
    assert unpack_array(flags).tolist() == [True, False, True]  # the layout is cached now
    with pytest.raises(ProtocolError, match="malformed"):
        unpack_array(flags[:-1] + b"\x02")  # same header: the bytes are still checked
    with pytest.raises(ProtocolError, match="shape"):
        unpack_array(flags[:-1])  # same header, one byte short
    with pytest.raises(ProtocolError, match="shape"):
        unpack_array(flags + b"\x01")
    with pytest.raises(ProtocolError, match="malformed"):
        unpack_array(flags[:6])  # a truncated header never matches a cached one


def test_cached_array_headers_follow_dtype_and_shape() -> None:
    for array in (
        np.arange(12, dtype=np.int32).reshape(3, 4),
        np.arange(12, dtype=np.float32).reshape(3, 4),
        np.arange(12, dtype=np.float32).reshape(4, 3),
        np.arange(12, dtype=">f4").reshape(4, 3),
        np.arange(12, dtype=np.float32).reshape(4, 3).T,
    ):
        for _ in range(2):  # the second encoding uses the cached header
            out = unpack_array(pack_array(array).data)
            assert out.dtype == array.dtype.newbyteorder("<") and np.array_equal(out, array)


def body_arrays(message) -> dict:
    """The body map as the decoder hands it to the schema (arrays decoded, read-only views)."""
    return decode(encode(message), LIMITS).to_body()


MUTATIONS = {
    "obs f64": lambda b: b | {"obs": b["obs"].astype(np.float64)},
    "obs big-endian": lambda b: b | {"obs": b["obs"].astype(">f4")},
    "obs 1-d": lambda b: b | {"obs": b["obs"].reshape(-1)},
    "obs 3-d": lambda b: b | {"obs": b["obs"][:, :, None]},
    "obs dim 0": lambda b: b | {"obs": b["obs"][:, :0], "next_obs": b["next_obs"][:, :0]},
    "obs nan": lambda b: b | {"obs": np.concatenate([np.full_like(b["obs"][:1], np.nan), b["obs"][1:]])},
    "next_obs inf": lambda b: b | {"next_obs": np.full_like(b["next_obs"], np.inf)},
    "next_obs shape": lambda b: b | {"next_obs": b["next_obs"][:, :-1]},
    "reward nan": lambda b: b | {"reward": np.full_like(b["reward"], np.nan)},
    "reward rows": lambda b: b | {"reward": b["reward"][:-1]},
    "reward 2-d": lambda b: b | {"reward": b["reward"][:, None]},
    "action i32": lambda b: b | {"action": b["action"].astype(np.int32)},
    "action high": lambda b: b | {"action": b["action"] + N_ACTIONS},
    "action negative": lambda b: b | {"action": b["action"] - N_ACTIONS},
    "env_ids i64": lambda b: b | {"env_ids": b["env_ids"].astype(np.int64)},
    "terminated u1": lambda b: b | {"terminated": b["terminated"].view(np.uint8)},
    "truncated rows": lambda b: b | {"truncated": np.concatenate([b["truncated"], [False]])},
    "obs list": lambda b: b | {"obs": b["obs"].tolist()},
    "actor empty": lambda b: b | {"actor": ""},
    "actor long": lambda b: b | {"actor": "a" * (LIMITS.max_string + 1)},
    "actor control": lambda b: b | {"actor": "a\nb"},
    "model int": lambda b: b | {"model": 3},
    "version negative": lambda b: b | {"policy_version": -1},
    "version bool": lambda b: b | {"policy_version": True},
    "version float": lambda b: b | {"policy_version": 1.0},
    "version huge": lambda b: b | {"policy_version": 2**63},
    "extra field": lambda b: b | {"extra": 1},
    "missing field": lambda b: {k: v for k, v in b.items() if k != "truncated"},
    "swapped field": lambda b: {("extra" if k == "truncated" else k): v for k, v in b.items()},
}


def full_checks(body: dict, limits: Limits) -> dict | ProtocolError:
    reader = BodyReader("transitions", body, limits)
    try:
        fields = TransitionBatch.read_body(reader)
        reader.finish()
    except ProtocolError as exc:
        return exc
    return fields


@settings(max_examples=300, deadline=None)
@given(
    n=st.integers(0, 40),
    dim=st.integers(1, 12),
    mutations=st.lists(st.sampled_from(sorted(MUTATIONS)), max_size=3),
    n_actions=st.sampled_from([N_ACTIONS, None]),
    max_batch=st.sampled_from([LIMITS.max_batch, 8]),
)
def test_fast_accept_is_sound(n, dim, mutations, n_actions, max_batch) -> None:
    """The fast path never accepts a body the full checks reject, and takes every valid one."""
    limits = Limits(n_actions=n_actions, max_batch=max_batch, max_obs_dim=10)
    body = body_arrays(small_transitions(n=n, dim=dim))
    for name in mutations:
        with contextlib.suppress(TypeError, IndexError, AttributeError, KeyError, ValueError):  # made moot
            body = MUTATIONS[name](body)
    fast = TransitionBatch.accept_body(body, limits)
    full = full_checks(body, limits)
    if fast is not None:
        assert not isinstance(full, ProtocolError), full
        assert fast.keys() == full.keys() and all(fast[k] is full[k] for k in fast)
    elif not mutations and n <= max_batch and dim <= 10:
        raise AssertionError("the fast path refused a valid batch")


def test_hot_path_is_taken_for_valid_batches() -> None:
    body = body_arrays(batch())
    assert TransitionBatch.accept_body(body, LIMITS) is not None
