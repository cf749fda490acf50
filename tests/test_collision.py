"""Process-wide state of coal that :mod:`sahgrasp.collision.hand_self` settles on import.

Each check runs in a fresh interpreter: the state under test is set once per process.
"""

import json
import subprocess
import sys

import pytest

# A cylinder against a turned box: in a fresh process, coal's box support is first asked about a
# direction without zero components, which settles the rule sahgrasp does not use.
_TURNED_BOX_QUERY = """
import coal, numpy as np
from scipy.spatial.transform import Rotation
rotation = Rotation.from_euler("xyz", [0.3, 0.5, 0.7]).as_matrix()
turned = coal.Transform3s(rotation, np.array([3.0, 0.2, 0.1]))
coal.distance(coal.Cylinder(0.5, 1.0), coal.Transform3s(), coal.Box(1.0, 1.0, 1.0), turned,
              coal.DistanceRequest(), coal.DistanceResult())
"""

# Two boxes side by side: the first direction has zero components, which settles the other rule.
_AXIS_BOX_QUERY = """
import coal, numpy as np
box, beside = coal.Box(1.0, 1.0, 1.0), coal.Transform3s(np.eye(3), np.array([3.0, 0.0, 0.0]))
coal.distance(box, coal.Transform3s(), box, beside, coal.DistanceRequest(), coal.DistanceResult())
"""

# Contact set 4 of the cup in `sahgrasp bench grasps --seed 7305411`: its collision repair with the
# cup reads box witnesses, and before the fix took 332 iterations in a fresh process and 338 after
# any earlier box query.
_CUP_SOLVE = """
from sahgrasp.model.hand import load_hand
from sahgrasp.ik import IKSettings, solve_ik
from sahgrasp.objects import load_object
from sahgrasp.objects.grasp_sampler import registered_reach, sample_object_grasps
cup = load_object("cup")
targets = sample_object_grasps(cup, 5, 1496828580, registered_reach("sah"))
hand = load_hand("sah")
result = solve_ik(hand, targets[4], IKSettings(), obstacle=cup)
print(json.dumps([result.iterations, result.q.tobytes().hex()]))
"""


def _run(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-W", "error::RuntimeWarning", "-c", "import json\n" + code],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    return done.stdout + done.stderr


def test_import_settles_the_box_rule_before_any_query() -> None:
    out = _run(
        "import sahgrasp.collision.hand_self as c\n"
        + _TURNED_BOX_QUERY
        + "print(c.settle_box_support())"
    )
    assert out.strip() == "True"


def test_a_box_query_before_the_import_is_reported() -> None:
    out = _run(_TURNED_BOX_QUERY + "import sahgrasp.collision.hand_self")
    assert "RuntimeWarning: coal answered a box query before sahgrasp.collision.hand_self" in out


def _solve_after(prelude: str) -> list[object]:
    last_line = _run(prelude + _CUP_SOLVE).strip().splitlines()[-1]
    return list(json.loads(last_line))


@pytest.mark.slow
@pytest.mark.parametrize("query", [_AXIS_BOX_QUERY, _TURNED_BOX_QUERY], ids=["axis", "turned"])
def test_object_solve_is_the_same_after_an_earlier_box_query(query: str) -> None:
    assert _solve_after("import sahgrasp.collision.hand_self\n" + query) == _solve_after("")
