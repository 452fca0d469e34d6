"""Small problem files that several test files start from and edit, written once here."""

# A noisy double integrator with two knots: position 1 (penalised and constrained) at t = 1,
# rest at t = 2. test_problem_errors.py edits it in one place per bad-input case.
BASE = """\
name = "di"
t0 = 0.0
x0 = [0.0, 0.0]
tick_hz = 10

[dynamics]
A = [[0, 1], [0, 0]]
B = [[0], [1]]
noise = [{ state = 1, G = [[0], [0.3]] }]

[cost]
Q = [[0, 0], [0, 0]]
R = [[1]]

[[knots]]
t = 1.0
penalty = { C = [[1, 0]], target = [1.0], weight = 2.0 }
constraint = { C = [[1, 0]], value = [1.0] }

[[knots]]
t = 2.0
constraint = { C = [[1, 0], [0, 1]], value = [0.0, 0.0] }
"""

# BASE with a per-stage input weight on stage 1 and a damped A on stage 2.
STAGES = BASE + """
[[stages]]
cost = { R = [[2]] }

[[stages]]
dynamics = { A = [[0, 1], [0, -1]] }
"""


def edit(base: str, *pairs: tuple[str, str]) -> str:
    """`base` with each ``(old, new)`` replaced; `old` must occur exactly once."""
    for old, new in pairs:
        assert base.count(old) == 1, f"{old!r} occurs {base.count(old)} times"
        base = base.replace(old, new)
    return base


def cart(*, name: str = "cart", t: str = "1.0", noise: bool = True) -> str:
    """The smallest problem: a double integrator that must reach position 1 at time `t`
    (noise on the velocity unless `noise` is false)."""
    noise_line = "noise = [{ state = 1, G = [[0], [0.3]] }]\n" if noise else ""
    return (f'name = "{name}"\nx0 = [0.0, 0.0]\ntick_hz = 10\n'
            f"[dynamics]\nA = [[0, 1], [0, 0]]\nB = [[0], [1]]\n{noise_line}"
            f"[cost]\nR = [[1]]\n"
            f"[[knots]]\nt = {t}\nconstraint = {{ C = [[1, 0]], value = [1.0] }}\n")
