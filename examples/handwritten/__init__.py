"""A hand-written CartPole server: the floor ``rlenv bench`` measures rlenv's speed against.

It does the work rlenv's CartPole does (``examples.cartpole``) and nothing else: the same pymunk
space (bodies, masses, moments, shapes, joints, gravity, damping, 60 ticks per second), the same
force on every tick, initial state, reward, termination and observation, so that the same seed
and actions give the same trajectory bit for bit. Around it: one blocking socket, one client,
``msgpack.unpackb`` / ``packb`` of length-prefixed frames (4 bytes, big-endian).

A request is a map with ``id`` and, applied in this order, ``config`` (``{"agent":
{"angle_limit": A}, "world": {"track_limit": T}}``), ``reset`` (``{"seed": S}``) and ``action``
(one float32 as raw bytes) with ``repeat_action`` (ticks, default 4; fewer if the pole falls).
The answer holds ``id``, ``observation`` (5 float32 as raw bytes), ``reward``, ``terminated``,
``truncated``, ``info`` and ``frames``.

What rlenv adds to this is everything else: checked requests and actions, errors that name
what is wrong, spaces, several clients, multi-instance servers, snapshots, inspection,
rendering, recording, real time. Run ``python -m examples.handwritten [K]``: it prints
``listening on HOST:PORT`` and exits when its client disconnects; with K, it serves K CartPoles
stepped in columns (:class:`CartPoles`), the floor of a vector step.
"""

from __future__ import annotations

import math
import socket
import struct
import sys
from typing import Any

import msgpack
import numpy as np
import pymunk

__all__ = ["CartPole", "CartPoles", "main", "serve"]

TICK = 1.0 / 60
MAX_FORCE = 10.0
POLE_LENGTH = 1.0


class CartPole:
    """rlenv's CartPole (``examples.cartpole``) in plain pymunk."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng()  # gymnasium's seeding.np_random(seed) is this
        self.angle_limit, self.track_limit = math.radians(12.0), 2.4

    def reset(self, seed: int | None = None) -> None:
        """A new space with the cart and the pole in a random initial state."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self.space = space = pymunk.Space()
        space.gravity, space.damping = (0.0, -9.81), 0.3
        track = pymunk.Body(body_type=pymunk.Body.STATIC)
        line = pymunk.Segment(track, (-self.track_limit, -0.2), (self.track_limit, -0.2), 0.01)
        line.sensor = True
        self.cart = cart = pymunk.Body(1.0, math.inf)
        box = pymunk.Poly.create_box(cart, (0.5, 0.25))
        self.pole = pole = pymunk.Body()
        stick = pymunk.Segment(pole, (0.0, 0.0), (0.0, POLE_LENGTH), 0.02)
        stick.mass = 0.1  # gives the pole its mass, moment and centre of gravity
        rail = pymunk.GrooveJoint(track, cart, (-100.0, 0.0), (100.0, 0.0), (0.0, 0.0))
        hinge = pymunk.PivotJoint(cart, pole, (0.0, 0.0))
        rail.collide_bodies = hinge.collide_bodies = False
        space.add(track, line, cart, box, pole, stick, rail, hinge)
        x, velocity, angle, spin = (float(v) for v in self.rng.uniform(-0.05, 0.05, size=4))
        self.limit_x = self.track_limit
        cart.position, cart.velocity = (x, 0.0), (velocity, 0.0)
        pole.angle = -angle  # angle first: pymunk turns a body about its centre of gravity
        pole.position, pole.angular_velocity, pole.velocity = (x, 0.0), -spin, (velocity, 0.0)

    def step(self, action: bytes, ticks: int) -> tuple[float, bool, int]:
        """Push for up to ``ticks`` ticks: the reward, whether the pole fell, the ticks run."""
        force = float(np.frombuffer(action, np.float32)[0]) * MAX_FORCE
        reward, fell, frames = 0.0, False, 0
        while frames < ticks and not fell:
            self.cart.apply_force_at_local_point((force, 0.0))
            self.space.step(TICK)
            frames += 1
            fell = (
                abs(self.pole.angle) > self.angle_limit or abs(self.cart.position.x) > self.limit_x
            )
            reward += 0.0 if fell else 1.0
        return reward, fell, frames

    def observe(self) -> bytes:
        """Cart x, pole centre x, pole angle, cart velocity, pole angular velocity."""
        cart, pole = self.cart, self.pole
        x_pole = pole.position.x - POLE_LENGTH / 2 * math.sin(pole.angle)
        return np.array(
            (cart.position.x, x_pole, -pole.angle, cart.velocity.x, -pole.angular_velocity),
            dtype=np.float32,
        ).tobytes()

    def answer(self, request: dict[str, Any]) -> dict[str, Any]:
        """Apply ``config``, ``reset`` and ``action`` in turn; the observation and outcome."""
        config = request.get("config", {})
        self.angle_limit = config.get("agent", {}).get("angle_limit", self.angle_limit)
        self.track_limit = config.get("world", {}).get("track_limit", self.track_limit)
        if "reset" in request:
            self.reset(request["reset"].get("seed"))
        reward, fell, frames = 0.0, False, 0
        if "action" in request:
            reward, fell, frames = self.step(request["action"], request.get("repeat_action", 4))
        return {
            "id": request["id"],
            "observation": self.observe(),
            "reward": reward,
            "terminated": fell,
            "truncated": False,
            "info": {},
            "frames": frames,
        }


def _receive(conn: socket.socket, size: int) -> bytes | None:
    """Exactly ``size`` bytes, or ``None`` when the client has gone."""
    data = b""
    while len(data) < size:
        chunk = conn.recv(size - len(data))
        if not chunk:
            return None
        data += chunk
    return data


class CartPoles:
    """K CartPoles answering one request in columns: the floor of a vector step.

    A request holds ``action`` (K float32 as raw bytes) and ``reset`` (K booleans: reset these
    instead of stepping them); the answer holds K observations, rewards (float64), flags (one
    byte each) and tick counts (int64), each column as raw bytes.
    """

    def __init__(self, count: int) -> None:
        self.poles = [CartPole() for _ in range(count)]
        for seed, pole in enumerate(self.poles):
            pole.reset(seed)

    def answer(self, request: dict[str, Any]) -> dict[str, Any]:
        """Reset or step every CartPole; the columns."""
        actions, resets = request["action"], request["reset"]
        observations, rewards, fell, frames = [], [], [], []
        for index, (pole, reset) in enumerate(zip(self.poles, resets, strict=True)):
            if reset:
                pole.reset()
                outcome = (0.0, False, 0)
            else:
                outcome = pole.step(actions[4 * index : 4 * index + 4], request["repeat_action"])
            observations.append(pole.observe())
            rewards.append(outcome[0])
            fell.append(outcome[1])
            frames.append(outcome[2])
        return {
            "id": request["id"],
            "observation": b"".join(observations),
            "reward": np.array(rewards).tobytes(),
            "terminated": bytes(fell),
            "frames": np.array(frames).tobytes(),
        }


def serve(listener: socket.socket, instances: int = 1) -> None:
    """Answer one client's requests until it disconnects (K CartPoles in columns if K > 1)."""
    conn, _ = listener.accept()
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    served = CartPole() if instances == 1 else CartPoles(instances)
    with conn:
        while (header := _receive(conn, 4)) is not None:
            body = _receive(conn, struct.unpack(">I", header)[0])
            if body is None:
                return
            reply = msgpack.packb(served.answer(msgpack.unpackb(body)))
            conn.sendall(struct.pack(">I", len(reply)) + reply)


def main() -> None:
    """Listen on 127.0.0.1 (a free port), say where, serve one client.

    ``python -m examples.handwritten K`` serves K CartPoles in columns.
    """
    instances = int(sys.argv[1]) if len(sys.argv) > 1 else 1
    with socket.create_server(("127.0.0.1", 0)) as listener:
        host, port = listener.getsockname()[:2]
        print(f"listening on {host}:{port}", flush=True)
        serve(listener, instances)
