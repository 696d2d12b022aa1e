"""What a user's model sends is checked where models run: a model that breaks the contract (docs/extending.md,
"What a model may send") or raises stops the run with one line naming the process, its model and the step,
the same on every backend, its own exception kept as the cause."""

import contextlib

import numpy as np
import pytest

from faulty_models import RAISE_FROM, FaultyRangeProcess, faulty_network
from tofnet.backends.registry import get_backend
from tofnet.cli import main
from tofnet.conformance import BackendRunner
from tofnet.errors import BackendError
from tofnet.io.recording import Recording
from tofnet.testing import TEST_INTRINSICS, moving_pattern

SENSOR = (24, 16)
BACKENDS = [("reference", {}), ("float", {}), ("fixed", {}), ("fixed", {"workers": 2}), ("multiproc", {"workers": 2})]


@pytest.fixture(scope="module")
def recording():
    return Recording(moving_pattern(SENSOR, (300, -150), 60_000, seed=1), intrinsics=TEST_INTRINSICS)


@pytest.fixture(scope="module")
def runners():
    """Each backend once (multiproc's workers start once for the module)."""
    with contextlib.ExitStack() as stack:
        yield {f"{name}{options}": BackendRunner(get_backend(name, **options), stack) for name, options in BACKENDS}


def refusal(runner, network, recording) -> BackendError:
    with pytest.raises(BackendError) as err:
        runner.run(network, recording)
    assert "\n" not in str(err.value)
    return err.value


def test_spikes_outside_the_size_stop_every_backend_with_the_same_line(runners, recording):
    """Before: fixed and float took them into the next row's state, multiproc dropped them all without a
    count, reference raised an IndexError."""
    network = faulty_network(SENSOR, "shift")
    messages = {name: str(refusal(runner, network, recording)) for name, runner in runners.items()}
    first = messages["reference{}"]
    assert first.startswith("process 'f' (FaultyModel) sent ") and " on f.passed outside its 24x16 size in " in first
    assert "(first x=" in first and "a model's spikes must lie within its port's size" in first
    sent = int(first.split(" sent ")[1].split(" spikes")[0].replace(",", ""))
    assert sent > 100
    assert set(messages.values()) == {first}, messages


def test_a_range_model_is_checked_alike(runners, recording):
    network = faulty_network(SENSOR, "shift", kind=FaultyRangeProcess)
    message = str(refusal(runners["fixed{}"], network, recording))
    assert message.startswith("process 'f' (FaultyRangeModel) sent ") and "outside its 24x16 size" in message
    assert str(refusal(runners["multiproc{'workers': 2}"], network, recording)) == message


@pytest.mark.parametrize("name", ["reference{}", "fixed{}", "fixed{'workers': 2}"])
def test_a_models_exception_is_one_line_naming_process_and_step(runners, recording, name):
    err = refusal(runners[name], faulty_network(SENSOR, "raise"), recording)
    message = str(err)
    assert message.startswith("process 'f' (FaultyModel), step ") and ": ValueError: boom in my model (at " in message
    assert int(message.split(", step ")[1].split(":")[0]) > RAISE_FROM
    assert "faulty_models.py:" in message
    assert isinstance(err.__cause__, ValueError) and err.__cause__.__traceback__ is not None  # the traceback kept


def test_an_interrupt_inside_a_model_stays_an_interrupt(runners, recording):
    """Not a model's failure: ``tofnet run`` says "interrupted" (exit 130) for it."""
    with pytest.raises(SystemError, match="interrupted in a kernel"):
        runners["fixed{}"].run(faulty_network(SENSOR, "interrupt"), recording)


def test_a_workers_model_exception_is_one_line_too(runners, recording):
    message = str(refusal(runners["multiproc{'workers': 2}"], faulty_network(SENSOR, "raise"), recording))
    assert message.startswith("multiproc worker ") and " failed while running chunk " in message
    assert ": process 'f' (FaultyModel), step " in message and "ValueError: boom in my model (at " in message


def test_a_range_models_exception_names_its_steps(runners, recording):
    message = str(refusal(runners["fixed{}"], faulty_network(SENSOR, "raise", kind=FaultyRangeProcess), recording))
    assert message.startswith("process 'f' (FaultyRangeModel), steps ") and ": ValueError: boom in my model" in message


@pytest.mark.parametrize("mode, expected", [
    ("port", "sent records on f.pased, which it does not declare (its output ports: passed)"),
    ("dtype", "sent records (x <i4, y <i4) of shape ("),
    ("list", "returned a list, expected a mapping of output port -> records (its ports: passed)"),
    ("float", "sent a float64 array of shape ("),
])
def test_a_broken_contract_says_what_was_expected(runners, recording, mode, expected):
    """Before: KeyError: 'pased', ValueError: no field of name step, AttributeError: 'list' object has no
    attribute 'items', ... with a traceback and no process named."""
    for name in ("reference{}", "fixed{}", "multiproc{'workers': 2}"):
        message = str(refusal(runners[name], faulty_network(SENSOR, mode), recording))
        assert "process 'f' (FaultyModel), step " in message and expected in message, (name, message)
        if mode in ("dtype", "float"):
            assert "expected a 1-D array of polarity records (step <i8, x <u2, y <u2, p |u1" in message


@pytest.mark.parametrize("mode, expected", [
    ("port", "sent records on f.pased, which it does not declare"),
    ("dtype", "sent records (x <u2, y <u2) of shape ("),
])
def test_a_range_models_broken_contract_names_its_steps(runners, recording, mode, expected):
    message = str(refusal(runners["fixed{}"], faulty_network(SENSOR, mode, kind=FaultyRangeProcess), recording))
    assert message.startswith("process 'f' (FaultyRangeModel), steps ") and expected in message


def test_tofnet_run_prints_the_one_line(tmp_path, recording, capsys):
    np.save(tmp_path / "events.npy", recording.events)
    spec = tmp_path / "faulty.yaml"
    spec.write_text("processes:\n"
                    "  input: {type: InputProcess, sensor_size: [24, 16]}\n"
                    "  f: {type: 'faulty_models:FaultyProcess', mode: shift}\n"
                    "  a: {type: BackgroundActivityFilterProcess}\n"
                    "connections:\n  - input.events -> f.events\n  - f.passed -> a.events\n")
    code = main(["run", str(tmp_path / "events.npy"), "--spec", str(spec), "--allow-import", "faulty_models",
                 "--out", str(tmp_path / "out.npz")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("tofnet run: error: process 'f' (FaultyModel) sent "), err
    assert "outside its 24x16 size" in err[-1] and "Traceback" not in "\n".join(err)
