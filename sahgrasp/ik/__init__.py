"""Inverse kinematics of the hand from contact points and normals (Claret & Suárez)."""

from sahgrasp.ik.batch import invalid_result, solve_many, worker_hand
from sahgrasp.ik.initial import (
    PAPER_TABLE1_LAMBDAS,
    PoseBasis,
    Sequence,
    default_sequence,
    hang_from_thumb,
    pose_basis,
)
from sahgrasp.ik.problems import random_problem, random_problems
from sahgrasp.ik.solver import REASONS, IKResult, IKSettings, solve_ik

__all__ = [
    "PAPER_TABLE1_LAMBDAS",
    "REASONS",
    "IKResult",
    "IKSettings",
    "PoseBasis",
    "Sequence",
    "default_sequence",
    "hang_from_thumb",
    "invalid_result",
    "pose_basis",
    "random_problem",
    "random_problems",
    "solve_ik",
    "solve_many",
    "worker_hand",
]
