"""Random waypoint courses and how well a flown path follows one.

A course is a polyline of waypoints (n_wp, 3) in NED metres; the craft starts at rest at
the origin (the course's first vertex, not itself a waypoint), heading north.

Measures of a flown path pos (N, 3) with target[k] = index of the waypoint being flown to:
- deviation d_k: distance from pos_k to the nearest point of the course polyline;
  rmse = sqrt(mean_k d_k^2) (the "position RMSE from the course");
- progress s_k: length of the legs already completed plus the projection of pos_k onto the
  current leg, clipped to [0, leg length]; the course is complete (s = L) once the last
  waypoint is reached. covered = s at the end of the allotted time; completion = covered / L.
- fitness = completion / (1 + rmse / d0) (paper section 3.3: proportional to the distance
  covered in the allotted time, inversely proportional to the deviation from the course);
  a flight that diverged scores that of the part it flew, minus 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpquad.control.config import CourseConfig


def random_course(cfg: CourseConfig, rng: np.random.Generator) -> np.ndarray:
    """Waypoints (legs, 3): each leg turns by U(-max_turn, max_turn) from the last heading,
    has length U(leg_min, leg_max) and changes altitude by U(-climb_max, climb_max)."""
    heading = 0.0
    here = np.zeros(3)
    out = np.empty((cfg.legs, 3))
    for i in range(cfg.legs):
        if i > 0:
            heading += np.deg2rad(rng.uniform(-cfg.max_turn_deg, cfg.max_turn_deg))
        length = rng.uniform(cfg.leg_min_m, cfg.leg_max_m)
        climb = rng.uniform(-cfg.climb_max_m, cfg.climb_max_m)
        here = here + np.array([length * np.cos(heading), length * np.sin(heading), climb])
        out[i] = here
    return out


def vertices(waypoints: np.ndarray) -> np.ndarray:
    """The polyline (n_wp + 1, 3): the origin, then the waypoints."""
    return np.vstack([np.zeros(3), waypoints])


def course_length(waypoints: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(vertices(waypoints), axis=0), axis=1).sum())


def allotted_steps(waypoints: np.ndarray, cfg: CourseConfig, dt: float) -> int:
    """Steps of the allotted time L / speed."""
    return max(1, int(np.ceil(course_length(waypoints) / cfg.speed_m_s / dt)))


def deviation(pos: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """Distance (N,) of each position to the nearest point of the course polyline."""
    v = vertices(waypoints)
    a, b = v[:-1], v[1:]
    ab = b - a
    rel = pos[:, None, :] - a[None, :, :]
    t = np.clip((rel * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(pos[:, None, :] - nearest, axis=-1).min(axis=1)


def progress(pos: np.ndarray, target: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """Distance (N,) along the course, from the leg each position is flying."""
    v = vertices(waypoints)
    legs = np.linalg.norm(np.diff(v, axis=0), axis=1)
    done = np.concatenate([[0.0], np.cumsum(legs)])
    n_wp = len(waypoints)
    leg = np.minimum(target, n_wp - 1)
    a, b = v[leg], v[leg + 1]
    along = np.clip(((pos - a) * (b - a)).sum(axis=1) / legs[leg], 0.0, legs[leg])
    return np.where(target >= n_wp, done[-1], done[leg] + along)


@dataclass
class PathScore:
    rmse_m: float
    covered_m: float
    length_m: float
    diverged: bool

    @property
    def completion(self) -> float:
        return self.covered_m / self.length_m

    def fitness(self, d0: float) -> float:
        f = self.completion / (1.0 + self.rmse_m / d0)
        return f - 1.0 if self.diverged else f

    def to_dict(self) -> dict:
        return {
            "rmse_m": self.rmse_m,
            "covered_m": self.covered_m,
            "length_m": self.length_m,
            "completion": self.completion,
            "diverged": self.diverged,
        }


def score_path(
    pos: np.ndarray, target: np.ndarray, waypoints: np.ndarray, flown: int, n_steps: int
) -> PathScore:
    """Score the flown part pos[: flown + 1] of a flight of n_steps."""
    p = pos[: flown + 1]
    w = target[: flown + 1]
    dev = deviation(p, waypoints)
    prog = progress(p, w, waypoints)
    return PathScore(
        float(np.sqrt(np.mean(dev**2))), float(prog[-1]), course_length(waypoints), flown < n_steps
    )
