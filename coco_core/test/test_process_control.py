"""The control protocol: typed messages over a real socket pair, one dispatcher on both ends."""

from __future__ import annotations

import logging
import socket
import threading

import pytest

from coco_core.processes.control import ControlLink
from coco_core.messages import Damage, Outcome, Result
from coco_core.processes.messages import ProfileRequest, Run, Start, Stop


@pytest.fixture
def pair():
    ours, theirs = socket.socketpair()
    launcher, child = ControlLink(ours.detach(), "process p"), ControlLink(theirs.detach(), "the launcher")
    yield launcher, child
    launcher.close()
    child.close()


def test_serve_runs_each_types_handler_until_the_word(pair) -> None:
    launcher, child = pair
    for message in (Damage("bag truncated"), Run(), Damage("frame size"), Start(), Damage("after")):
        assert launcher.send(message)
    seen: list[object] = []
    word = child.serve({Damage: lambda message: seen.append(message.what), Run: seen.append}, until=(Start, Stop))
    assert word == Start()
    assert seen == ["bag truncated", Run(), "frame size"], "in order, and nothing after the word"
    assert child.receive(timeout=5) == Damage("after")


def test_a_request_is_answered_through_the_other_ends_dispatcher(pair) -> None:
    launcher, child = pair
    outcomes: list[Outcome] = []

    def answer(request: ProfileRequest) -> None:
        child.answer(request, Outcome(True, {"process": "p", "request": request.id}))
        if request.id == 2:
            child.send(Stop("answered"))

    server = threading.Thread(target=child.serve, args=({ProfileRequest: answer},), daemon=True)
    server.start()
    launcher.request(ProfileRequest(), outcomes.append)
    launcher.request(ProfileRequest(), outcomes.append)
    assert launcher.serve({}, until=(Stop,)) == Stop("answered"), "the Results went to the requests"
    assert outcomes == [Outcome(True, {"process": "p", "request": 1}), Outcome(True, {"process": "p", "request": 2})]
    launcher.close()  # the child's dispatcher ends when the link closes
    server.join(5)
    assert not server.is_alive()


def test_a_message_without_a_handler_is_counted_and_logged_and_a_closed_peer_fails_requests(pair, caplog) -> None:
    launcher, child = pair
    launcher.send(Run())
    launcher.send(Run())
    launcher.send(Stop("end"))
    with caplog.at_level(logging.ERROR, logger="coco"):
        assert child.serve({}, until=(Stop,)) == Stop("end")
    assert "control link with the launcher: unexpected Run() (2 so far)" in caplog.text
    assert child.unexpected == 2 and launcher.unexpected == 0
    child.close()
    failures: list[Outcome] = []
    launcher.request(ProfileRequest(), failures.append)
    launcher.request(ProfileRequest(), failures.append)
    launcher.abandon("process p ended")
    assert failures and all(not outcome.ok and outcome.type == "ProcessError" for outcome in failures)


def test_a_result_for_no_request_is_ignored(pair) -> None:
    launcher, child = pair
    child.send(Result(99, Outcome(True, 1)))
    child.send(Stop("end"))
    assert launcher.serve({}, until=(Stop,)) == Stop("end")
