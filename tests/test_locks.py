"""The lean SimPy parts of the locks (fleet_sim.sim.traffic.locks): a claim granted at once built
directly (`Lock.claim`), a lock let go of with a `Released` event instead of SimPy's `Release`,
and a wait for a claim or a timeout with `FirstOf` instead of SimPy's `Condition`. The outcome
must be SimPy's, event for event: the same clients get the same locks at the same instants in
the same order, with every lock holding and queueing the same claims at every step."""

from __future__ import annotations

import random
from collections.abc import Generator, Mapping
from typing import Any

import pytest
import simpy

from fleet_sim.config.layout import BACKWARD, FORWARD
from fleet_sim.sim.traffic.deadlock import find_cycle
from fleet_sim.sim.traffic.locks import Claim, FirstOf, Lock, NodeLock, ZoneLock
from fleet_sim.sim.traffic.waking import Relay
from fleet_sim.sim.traffic.zones import DirectedClaim, DirectionGate, Gate


def _script(seed: int, lean: bool, env: simpy.Environment | None = None) -> list[tuple[Any, ...]]:
    """Clients taking and giving back a few locks (one a gate of two), every time a whole
    second so that many things happen in the same instant, some giving a lock back in the
    instant they got it or asking again before giving it back, some waiting with a timeout;
    each step logged with what every lock holds and queues then. `lean`: the locks' own parts,
    else SimPy's. `env`: a SimPy environment by default."""
    env = env if env is not None else simpy.Environment()
    rng = random.Random(seed)
    locks: list[Lock] = [Lock(env, NodeLock(f"n{i}")) for i in range(3)]
    locks.append(Gate(env, ZoneLock("z"), 2))
    log: list[tuple[Any, ...]] = []

    def note(cid: int, what: str, at: int) -> None:
        log.append((env.now, cid, what, at, tuple(len(lk.users) for lk in locks),
                    tuple(len(lk.put_queue) for lk in locks)))

    def claim(lock: Lock, cid: int) -> Claim:
        return lock.claim(cid) if lean else Claim(lock, cid)

    def release(lock: Lock, claim: Claim) -> None:
        if lean:
            lock.release(claim)
        else:
            simpy.Resource.release(lock, claim)

    def either(claim: Claim, delay: float) -> simpy.Event:
        timeout = env.timeout(delay)
        return FirstOf(env, claim, timeout) if lean else claim | timeout

    def client(cid: int) -> Generator[simpy.Event, Any, None]:
        yield env.timeout(rng.randrange(3))
        for _ in range(15):
            at = rng.randrange(len(locks))
            lock = locks[at]
            held = claim(lock, cid)
            note(cid, "asked", at)
            while not held.triggered:
                yield either(held, rng.choice((1, 2)))
                note(cid, "looked", at)
                if not held.triggered and rng.random() < 0.2:
                    held.cancel()
                    note(cid, "gave up", at)
                    break
            if not held.triggered:
                continue
            note(cid, "got", at)
            hold = rng.choice((0, 0, 1, 2))
            if hold:
                yield env.timeout(hold)
            elif rng.random() < 0.5:
                yield env.timeout(0)
            if rng.random() < 0.3:  # asks again (queued if full), then gives the first back
                again = claim(lock, cid)
                note(cid, "asked again", at)
                release(lock, held)
                note(cid, "freed", at)
                if not again.triggered:
                    yield either(again, 1)
                    note(cid, "looked", at)
                held = again
                if not held.triggered:
                    held.cancel()
                    note(cid, "gave up", at)
                    continue
            release(lock, held)
            note(cid, "freed", at)
            if rng.random() < 0.5:
                yield env.timeout(rng.choice((0, 1)))

    for cid in range(10):
        env.process(client(cid))
    env.run(until=200)
    return log


@pytest.mark.parametrize("seed", range(30))
def test_lean_parts_behave_as_simpy(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Event for event, with every release scheduling its `Released` event as SimPy's does."""
    monkeypatch.setattr(Lock, "QUIET_RELEASE", False)
    assert _script(seed, lean=True) == _script(seed, lean=False)


def test_a_release_with_nobody_waiting_schedules_no_event() -> None:
    """`Lock.QUIET_RELEASE`: let go of with nobody waiting, a lock schedules nothing and is
    free at once (a claim in the same instant is granted while being made); with a claim
    waiting, it schedules the `Released` that grants it; a same-direction zone always does."""
    env = simpy.Environment()
    lock = Lock(env, NodeLock("n"))
    first = lock.claim(1)
    queued_before = len(env._queue)
    assert lock.release(first) is None and len(env._queue) == queued_before
    second = lock.claim(2)
    assert second.triggered and lock.holder == 2
    waiting = lock.claim(3)
    assert not waiting.triggered
    assert lock.release(second) is not None
    env.run()
    assert waiting.processed and lock.holder == 3
    zone = DirectionGate(env, ZoneLock("d"), None)
    claim = DirectedClaim(zone, 1, FORWARD)
    assert claim.triggered and zone.release(claim) is not None


@pytest.mark.parametrize("holder_goes_on", [False, True])
def test_a_claim_granted_from_the_queue_is_processed_at_once_only_when_it_would_be_next(
        holder_goes_on: bool) -> None:
    """Client 1 lets go of the lock at 1 s, client 2 waits for it (through a `Relay`, as a
    blocked AGV does). With nothing else queued for 1 s, the `Released` event's grant and the
    relay are processed there and then: one event where SimPy's parts process three. If client
    1 goes on in the same instant after its release (a timeout of 0, queued before the grant),
    the grant is scheduled, and client 1 goes on before client 2 resumes, as SimPy has it."""
    env = simpy.Environment()
    lock = Lock(env, NodeLock("n"))
    log: list[str] = []
    processed = [0]
    step = env.step

    def counted_step() -> None:
        processed[0] += bool(env._queue)  # (the last call finds the queue empty)
        step()

    env.step = counted_step  # type: ignore[method-assign]

    def holder() -> Any:
        claim = lock.claim(1)
        yield env.timeout(1.0)
        lock.release(claim)
        if holder_goes_on:
            yield env.timeout(0.0)
            log.append(f"1 goes on at {env.now:g}")
        yield env.timeout(10.0)  # (its end, queued for 1 s, would come before the grant)

    def waiter() -> Any:
        yield env.timeout(0.5)
        claim = lock.claim(2)
        assert not claim.triggered
        yield Relay(env, claim)
        log.append(f"2 holds at {env.now:g}")

    env.process(holder())
    env.process(waiter())
    env.run()
    assert lock.holder == 2
    if holder_goes_on:
        assert log == ["1 goes on at 1", "2 holds at 1"]
    else:
        assert log == ["2 holds at 1"]
        # two Initialize, three timeouts, Released, two process ends: no Claim, no Relay
        assert processed[0] == 8


def _find_cycle_by_search(start: int, waiting: Mapping[int, Lock]) -> list[int] | None:
    """`find_cycle` as it was: depth first over every lock's blockers (the reference)."""
    lock = waiting.get(start)
    if lock is None:
        return None
    chain = [start]
    seen = {start}
    stack = [iter(lock.blockers(start))]
    while stack:
        client = next(stack[-1], None)
        if client is None:
            stack.pop()
            chain.pop()
            continue
        if client == start:
            return chain
        if client in seen:
            continue
        seen.add(client)
        lock = waiting.get(client)
        if lock is None:
            continue
        chain.append(client)
        stack.append(iter(lock.blockers(client)))
    return None


@pytest.mark.parametrize("seed", range(200))
def test_find_cycle_walks_chains_as_the_search_did(seed: int) -> None:
    """Random wait-for graphs over node locks, a gate of two and same-direction zones (which
    may name several blockers): the same cycle, or none, from every client."""
    rng = random.Random(seed)
    env = simpy.Environment()
    locks: list[Lock] = [Lock(env, NodeLock(f"n{i}")) for i in range(6)]
    locks.append(Gate(env, ZoneLock("z"), 2))
    locks += [DirectionGate(env, ZoneLock(f"d{i}"), None) for i in range(2)]
    clients = list(range(8))
    for lock in locks:  # holders first
        for cid in rng.sample(clients, rng.randrange(3)):
            if isinstance(lock, DirectionGate):
                DirectedClaim(lock, cid, rng.choice((FORWARD, BACKWARD)))
            else:
                Claim(lock, cid)
    waiting: dict[int, Lock] = {}
    for cid in clients:  # then each client waits for one lock, or for none
        if rng.random() < 0.8:
            lock = rng.choice(locks)
            if isinstance(lock, DirectionGate):
                DirectedClaim(lock, cid, rng.choice((FORWARD, BACKWARD)))
            else:
                Claim(lock, cid)
            waiting[cid] = lock
    for cid in clients:
        assert find_cycle(cid, waiting) == _find_cycle_by_search(cid, waiting)
