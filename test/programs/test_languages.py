"""The robot-program languages: vendor conventions as known answers, byte-identical round
trips of programs in each language's documented syntax, and bad programs."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from robot_calib.errors import InputError
from robot_calib.kinematics.loader import load_robot
from robot_calib.programs.registry import language_for
from robot_calib.programs.source import rewrite

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples" / "programs"
MAIN = {
    "krl": "pick_place.src",
    "rapid": "pick_place.mod",
    "fanuc_tp": "pick_place.ls",
    "urscript": "pick_place.script",
}


def _flange(robot: str, degrees: list[float]) -> np.ndarray:
    return load_robot(robot).nominal_frames(np.radians([degrees]))[:, -1]


# Each vendor's pose at a pose its documentation draws, from the published dimensions
# (the description's comment names them): KUKA's home {A1 0, A2 -90, A3 90, A4 0, A5 0,
# A6 0}, ABB's calibration position (all axes 0), FANUC's J5 = -90 (the faceplate down),
# Universal Robots' upright pose (shoulder and wrist 1 at -90 deg).
KNOWN = [
    ("krl", "kr16_2", [0, -90, 90, 0, 0, 0], [1088.0, 0.0, 1320.0, 0.0, 90.0, 0.0], (2, 2)),
    (
        "rapid",
        "irb2600_12_165",
        [0, 0, 0, 0, 0, 0],
        [1030.0, 0.0, 1260.0, np.sqrt(0.5), 0.0, np.sqrt(0.5), 0.0],
        (0, 0, 0, 0),
    ),
    (
        "fanuc_tp",
        "m20ia",
        [0, 0, 0, 0, -90, 0],
        [985.0, 0.0, 940.0, 180.0, 0.0, 0.0],
        (0, 1, 1, 0, 0, 0),
    ),
    (
        "urscript",
        "ur10",
        [0, -90, 0, -90, 0, 0],
        [0.0, -0.2561, 1.4273, 0.0, np.pi / np.sqrt(2), -np.pi / np.sqrt(2)],
        None,
    ),
]


@pytest.mark.parametrize(("name", "robot", "degrees", "expected", "config"), KNOWN)
def test_vendor_pose_of_a_documented_pose(
    name: str, robot: str, degrees: list[float], expected: list[float], config: object
) -> None:
    language = language_for("x", name)
    old = np.array([expected])
    values = language.base_to_pose(_flange(robot, degrees), old)[0]
    tolerance = np.array([1e-3] * 3 + [1e-6] * (len(expected) - 3))  # mm (UR m), deg/1
    if name in ("krl", "fanuc_tp"):
        tolerance[3:] = 1e-6
        values[3:] = (values[3:] - old[0, 3:] + 180.0) % 360.0 - 180.0 + old[0, 3:]
    np.testing.assert_allclose(values, expected, atol=float(tolerance.max()) * 10)
    if config is not None:
        assert language.configuration is not None
        assert language.configuration(load_robot(robot), np.radians([degrees]))[0] == config


def test_euler_and_quaternion_rules() -> None:
    """KUKA A, B, C turn about z, the new y, the newest x; FANUC W, P, R about the fixed
    x, y, z; ABB's quaternion is [w, x, y, z]; URScript's a rotation vector."""
    krl, fanuc = language_for("x", "krl"), language_for("x", "fanuc_tp")
    rapid, ur = language_for("x", "rapid"), language_for("x", "urscript")
    a90 = krl.pose_to_base(np.array([[0, 0, 0, 90.0, 0, 0]]))[0, :3, :3]
    np.testing.assert_allclose(a90 @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # x turned onto y
    b90 = krl.pose_to_base(np.array([[0, 0, 0, 0, 90.0, 0]]))[0, :3, :3]
    np.testing.assert_allclose(b90 @ [0, 0, 1], [1, 0, 0], atol=1e-12)  # z forward
    both = krl.pose_to_base(np.array([[0, 0, 0, 90.0, 90.0, 0]]))[0, :3, :3]
    np.testing.assert_allclose(both, a90 @ b90, atol=1e-12)  # B about the turned y
    wpr = fanuc.pose_to_base(np.array([[0, 0, 0, 90.0, 90.0, 0]]))[0, :3, :3]
    w90 = fanuc.pose_to_base(np.array([[0, 0, 0, 90.0, 0, 0]]))[0, :3, :3]
    np.testing.assert_allclose(wpr, b90 @ w90, atol=1e-12)  # P about the fixed y, after W
    down = rapid.pose_to_base(np.array([[0, 0, 0, 0, 0, 1.0, 0]]))[0, :3, :3]  # [w x y z]
    np.testing.assert_allclose(down @ [0, 0, 1], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(
        ur.pose_to_base(np.array([[0, 0, 0, 0, np.pi, 0]]))[0, :3, :3], down, atol=1e-12
    )
    assert krl.pose_to_base(np.array([[1000.0, 0, 0, 0, 0, 0]]))[0, 0, 3] == pytest.approx(1.0)
    assert ur.pose_to_base(np.array([[1.0, 0, 0, 0, 0, 0]]))[0, 0, 3] == pytest.approx(1.0)


@pytest.mark.parametrize("name", sorted(MAIN))
def test_round_trip_is_byte_identical(name: str, tmp_path: Path) -> None:
    language = language_for("x", name)
    for path in EXAMPLES.glob("pick_place.*"):
        shutil.copy(path, tmp_path)
    program = language.read(tmp_path / MAIN[name])
    assert program.targets and all(t.used for t in program.targets)
    for file, text in program.texts.items():
        assert text.encode() == (tmp_path / file).read_bytes()
    same = {k: t.values for k, t in enumerate(program.targets)}  # written again as read
    places = {k: tuple(0 for _ in t.values) for k, t in enumerate(program.targets)}
    again = rewrite(program, same, places)
    for file, text in again.items():
        original = (tmp_path / file).read_bytes()
        if name == "rapid" or name == "krl":
            assert b"\r\n" in original  # the controllers' own line ends
        assert text.encode() == original


@pytest.mark.parametrize("name", sorted(MAIN))
def test_new_numbers_read_back_as_written(name: str, tmp_path: Path) -> None:
    """Every target moved by a few hundredths: written at the language's decimals, read
    back to within them, and nothing else changed (the text between numbers)."""
    language = language_for("x", name)
    for path in EXAMPLES.glob("pick_place.*"):
        shutil.copy(path, tmp_path)
    program = language.read(tmp_path / MAIN[name])
    unit = name == "rapid"  # a quaternion stays a unit quaternion: positions moved only
    moved = {
        k: tuple(
            v + (0.0 if unit and t.kind == "pose" and i >= 3 else 0.0123456 * (i + 1))
            for i, v in enumerate(t.values)
        )
        for k, t in enumerate(program.targets)
    }
    places = {k: language.places(t.kind, len(t.values)) for k, t in enumerate(program.targets)}
    out = tmp_path / "out"
    out.mkdir()
    for file, text in rewrite(program, moved, places).items():
        (out / file).write_bytes(text.encode(program.encoding(file)))
    again = language.read(out / MAIN[name])
    for k, target in enumerate(again.targets):
        step = 10.0 ** -np.array(places[k], dtype=float)
        assert np.all(np.abs(np.subtract(target.values, moved[k])) <= step / 2 + 1e-12)


def test_rewrite_keeps_crlf_and_comments(tmp_path: Path) -> None:
    language = language_for("x", "rapid")
    text = (
        "MODULE m ! a comment with [1,2,3] in it\r\n"
        "  CONST jointtarget j1:=[[1,2,3,4,5,6],[9E9,9E9,9E9,9E9,9E9,9E9]]; ! MoveL j2\r\n"
        "  PROC main()\r\n    MoveAbsJ j1, v100, fine, tool0;\r\n  ENDPROC\r\nENDMODULE\r\n"
    )
    (tmp_path / "m.mod").write_bytes(text.encode())
    program = language.read(tmp_path / "m.mod")
    (target,) = program.targets
    out = rewrite(program, {0: (1.5, 2, 3, 4, 5, 6)}, {0: (3,) * 6})["m.mod"]
    assert out == text.replace("[[1,2,3,4,5,6]", "[[1.500,2,3,4,5,6]")  # the rest as it was


def _ls(position: str) -> str:
    """A FANUC .ls moving to P[1] with the /POS body `position` (P[1] on line 5)."""
    return f"/PROG P\n/MN\n 1:J P[1] 100% FINE ;\n/POS\nP[1]{{\n GP1:\n{position}\n}};\n/END\n"


def _mod(body: str) -> str:
    return f"MODULE m\n{body}\nENDMODULE\n"


XYZ = " X = 1 mm, Y = 2 mm, Z = 3 mm,\n W = 0 deg, P = 0 deg"
MOVE_P1 = " PROC main()\n  MoveL p1, v100, fine, tool0;\n ENDPROC"
KRL_DAT = "DEFDAT p\nDECL E6POS XP1={X 1,Y 2,Z 3,A 0,B 90,C 0,S 2,T 2}\nENDDAT\n"
BAD = [
    (
        "krl",
        {"p.src": "DEF p()\nPTP XP1\nEND\n", "p.dat": KRL_DAT.replace("X 1,", "X 463.1.63,")},
        "p.dat:2: '463.1.63' is not a number",
    ),
    (
        "krl",
        {"p.src": "DEF p()\nPTP XP1\nEND\n", "p.dat": KRL_DAT.replace("Y 2,", "Y 2,Y 3,")},
        "p.dat:2: component Y given twice",
    ),
    (
        "krl",
        {"p.src": "DEF p()\nPTP XP1\nEND\n", "p.dat": KRL_DAT.replace("C 0,", "C 0 ")},
        "p.dat:2: 'C 0 S 2': expected NAME value",
    ),
    (
        "krl",
        {"p.src": "DEF p()\nPTP XP1\nEND\n", "p.dat": KRL_DAT.replace("Z 3", "Z 1e999")},
        "p.dat:2: 1e999 is beyond",
    ),
    (
        "krl",
        {"p.src": "DEF p()\n$TOOL = MYTOOL\nPTP XP1\nEND\n", "p.dat": KRL_DAT},
        "p.src:2: $TOOL = MYTOOL: a frame this reader cannot resolve",
    ),
    ("krl", {"p.src": "DEF p()\nPTP XP1\nEND\n"}, "no such position declared in p.src (no p.dat"),
    (
        "krl",
        {"p.src": "DEF p()\nPTP XP9\nEND\n", "p.dat": "DEFDAT p\nENDDAT\n"},
        "p.src:2: PTP to XP9: no such position declared",
    ),
    ("krl", {"p.src": "DEF p()\nPTP {A1 0,A2 -90\nEND\n"}, "p.src:2: aggregate without"),
    ("rapid", {"m.mod": _mod(MOVE_P1)}, "m.mod:3: MoveL to p1: no robtarget or jointtarget"),
    (
        "rapid",
        {"m.mod": _mod(" CONST robtarget p1:=[[1,2,3],[1,0,0,0]];")},
        "m.mod:2: p1: robtarget: expected [[x,y,z],[q1..q4],[cf1,cf4,cf6,cfx],[eax]]",
    ),
    (
        "rapid",
        {"m.mod": _mod(" CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0];")},
        "m.mod:2: '[' without its closing ']'",
    ),
    (
        "fanuc_tp",
        {"p.ls": "/PROG P\n/MN\n 1:J P[2] 100% FINE ;\n/POS\n/END\n"},
        "p.ls:3: a motion to P[2]: not in the /POS section",
    ),
    ("fanuc_tp", {"p.ls": _ls(" UF : 0, UT : 0,\n" + XYZ)}, "p.ls:5: P[1] lacks R"),
    (
        "fanuc_tp",
        {"p.ls": _ls(" UF : 0, UT : 0, CONFIG : 'Q U T, 0, 0, 0',\n" + XYZ + ", R = 0 deg")},
        "CONFIG 'Q U T, 0, 0, 0': expected",
    ),
    (
        "fanuc_tp",
        {"p.ls": _ls(" UF : 0, UT : 0, CONFIG : 'N U T, 0, 0',\n" + XYZ + ", R = 0 deg")},
        "CONFIG 'N U T, 0, 0': expected",
    ),
    (
        "fanuc_tp",
        {"p.ls": _ls(" UF : 0, UT : 0,\n" + XYZ.replace("1 mm", "1 m") + ", R = 0 deg")},
        "p.ls:5: 'X = 1 m': expected X in mm",
    ),
    (
        "fanuc_tp",
        {"p.ls": _ls(" UF : 0, UT : 0,\n" + XYZ.replace("2 mm", "583.5.30 mm") + ", R = 0 deg")},
        "p.ls:8: '583.5.30' is not a number",
    ),
    (
        "rapid",
        {
            "m.mod": _mod(
                " CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
            )
        },
        "p1: robtarget robconf: expected [4 numbers]",
    ),
    (
        "rapid",
        {
            "m.mod": _mod(
                " CONST robtarget p1:=[[1,2,3],[0,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
            )
        },
        "p1: robtarget: quaternion of norm 0, not 1",
    ),
    (
        "rapid",
        {
            "m.mod": _mod(
                " CONST robtarget p1:=[[1,2,1e309],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
            )
        },
        "m.mod:2: 1e309 is beyond",
    ),
    (
        "rapid",
        {"m.mod": _mod(' PERS wobjdata w:=[FALSE,TRUE,"",[[1,2,3]],[[0,0,0],[1,0,0,0]]];')},
        "wobjdata w uframe: expected [[x,y,z],[q1,q2,q3,q4]]",
    ),
    (
        "urscript",
        {"s.script": "def s():\n  movel(target, a=1)\nend\n"},
        "s.script:2: movel to target: not assigned",
    ),
    (
        "urscript",
        {"s.script": "def s():\n  movel(p[0.1, 0.2, 0.3], a=1)\nend\n"},
        "s.script:2: line 2: p[...] with 3 numbers, expected 6",
    ),
    (
        "urscript",
        {"s.script": "def s():\n  movel(p[0.1, 0.2, 1e400, 0, 0, 0], a=1)\nend\n"},
        "s.script:2: 1e400 is beyond",
    ),
    (
        "urscript",
        {"s.script": "def s():\n  set_tcp(t)\n  movej([0,0,0,0,0,0])\nend\n"},
        "s.script:2: set_tcp(t): not a p[...] assigned above",
    ),
]


@pytest.mark.parametrize(("name", "files", "message"), BAD)
def test_bad_programs_name_file_and_line(
    name: str, files: dict[str, str], message: str, tmp_path: Path
) -> None:
    for file, text in files.items():
        (tmp_path / file).write_text(text)
    language = language_for("x", name)
    main = next(f for f in files if Path(f).suffix in language.suffixes)
    with pytest.raises(InputError, match=None) as raised:
        language.read(tmp_path / main)
    assert message in str(raised.value)
    assert "\n" not in str(raised.value)


def test_language_from_suffix_and_unknown_suffix() -> None:
    assert language_for("a/b/PROG.SRC").name == "krl"
    assert language_for("x.modx").name == "rapid"
    with pytest.raises(InputError, match=r"prog\.txt: no robot-program language reads \.txt"):
        language_for("prog.txt")
    with pytest.raises(InputError, match="`language='cobol'`"):
        language_for("x.src", "cobol")


def test_what_the_readers_leave_or_name(tmp_path: Path) -> None:
    """Text in strings is no motion; a target changed at run time, moved to relatively or
    through an expression is left or named; Windows-1252 files are read and kept."""
    ur = language_for("x", "urscript")
    (tmp_path / "s.script").write_text(
        "def s():\n"
        '  textmsg("movel(p[1, 2, 3, 4, 5, 6])")\n'
        "  a = p[0.4, 0.1, 0.3, 0, 3.14, 0]\n"
        "  movel(a)\n"
        "  a[2] = 0.5\n"
        "  b = pose_trans(a, p[0, 0, 0.1, 0, 0, 0])\n"
        "  movel(b)\n"
        "end\n"
    )
    program = ur.read(tmp_path / "s.script")
    assert [t.name for t in program.targets] == ["a (line 3)"]  # not the string's p[...]
    assert "changed at run time on line 5" in program.targets[0].note
    assert any("b, set by an expression" in r for r in program.remarks)
    krl = language_for("x", "krl")
    (tmp_path / "w.src").write_bytes(
        "DEF w()\n; Greifer schließen\nLIN_REL {X 10,Y 0,Z 0,A 0,B 0,C 0}\n"
        "PTP XP1\nLIN XP1:{X 5}\nXP2.Z = 10\nPTP XP2\nEND\n".encode("cp1252")
    )
    dat = KRL_DAT.replace("DEFDAT p", "DEFDAT w")
    (tmp_path / "w.dat").write_text(
        dat.replace("ENDDAT", "DECL E6AXIS XP2={A1 0,A2 -90,A3 90,A4 0,A5 0,A6 0}\nENDDAT")
    )
    program = krl.read(tmp_path / "w.src")
    assert program.encoding("w.src") == "cp1252"
    assert "schließen" in program.texts["w.src"]
    notes = {t.name: t.note for t in program.targets}
    assert "relative motion" in notes["line 3"]
    assert "geometric operator" in notes["XP1"]
    assert "changed at run time on line 6" in notes["XP2"]
    rapid = language_for("x", "rapid")
    (tmp_path / "m.mod").write_text(
        _mod(
            " CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
            ' PROC main()\n  TPWrite "MoveL p9, v1, fine, tool0;";\n'
            "  MoveLDO p1, v100, fine, tGrip, doGrip, 1;\n  p1.trans.z := 5;\n ENDPROC"
        )
    )
    program = rapid.read(tmp_path / "m.mod")
    (target,) = program.targets
    assert target.tool == "tgrip"  # the tool argument, not the signal value
    assert "changed at run time" in target.note


def test_instructions_the_readers_do_not_follow_are_named_or_refused(tmp_path: Path) -> None:
    krl = language_for("x", "krl")
    dat = KRL_DAT.replace(
        "ENDDAT",
        "DECL E6POS XP2={X 4,Y 5,Z 6,A 0,B 90,C 0}\n"
        "DECL E6POS XP3={X 7,Y 8,Z 9,A 0,B 90,C 0}\nENDDAT",
    )
    (tmp_path / "k.dat").write_text(dat.replace("DEFDAT p", "DEFDAT k"))
    (tmp_path / "k.src").write_text(
        "DEF k()\nPTP XP1\nLIN XP1:XP2\nSPLINE\n  SPL XP3\nENDSPLINE\nEND\n"
    )
    notes = {t.name: (t.used, t.note) for t in krl.read(tmp_path / "k.src").targets}
    assert "geometric operator" in notes["XP1"][1]
    assert "named on line 3" in notes["XP2"][1] and "named on line 5" in notes["XP3"][1]
    (tmp_path / "b.src").write_text("DEF b()\nBAS(#TOOL, tn)\nPTP XP1\nEND\n")
    (tmp_path / "b.dat").write_text(KRL_DAT.replace("DEFDAT p", "DEFDAT b"))
    with pytest.raises(InputError, match=r"b\.src:2: BAS\(#TOOL, tn\): a frame this reader"):
        krl.read(tmp_path / "b.src")
    ur = language_for("x", "urscript")
    (tmp_path / "u.script").write_text(
        "def u():\n  set_tcp(pose_trans(t, p[0,0,0.1,0,0,0]))\n  movej([0,0,0,0,0,0])\nend\n"
    )
    with pytest.raises(InputError, match=r"u\.script:2: set_tcp\(pose_trans"):
        ur.read(tmp_path / "u.script")
    rapid = language_for("x", "rapid")
    (tmp_path / "r.mod").write_text(
        _mod(
            " PERS tooldata g:=[TRUE,[[0,0,200],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n"
            " CONST jointtarget j1:=[[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
            " PROC main()\n  MoveAbsJ j1, v100, fine, g;\n  g.tframe.trans.z := 250;\n ENDPROC"
        )
    )
    with pytest.raises(InputError, match=r"r\.mod:6: g changed at run time"):
        rapid.read(tmp_path / "r.mod")


def test_a_fanuc_position_used_by_an_assignment_is_named(tmp_path: Path) -> None:
    fanuc = language_for("x", "fanuc_tp")
    body = " UF : 0, UT : 0,\n" + XYZ + ", R = 0 deg"
    text = _ls(body).replace(" 1:J P[1] 100% FINE ;", " 1:J P[1] 100% FINE ;\n 2:  PR[2]=P[2] ;")
    text = text.replace("/END", "P[2]{\n GP1:\n" + body + "\n};\n/END")
    (tmp_path / "p.ls").write_text(text)
    notes = {t.name: t.note for t in fanuc.read(tmp_path / "p.ls").targets}
    assert notes["P[1]"] == "" and "named on line 4" in notes["P[2]"]


def test_an_axis_target_serves_every_base(tmp_path: Path) -> None:
    """Axis values put the tool where they put it whatever base is active: one target,
    moved to under two bases, is compensated (a Cartesian one is not)."""
    krl = language_for("x", "krl")
    (tmp_path / "h.dat").write_text(
        "DEFDAT h\nDECL E6AXIS XH={A1 0,A2 -90,A3 90,A4 0,A5 30,A6 0}\nENDDAT\n"
    )
    (tmp_path / "h.src").write_text(
        "DEF h()\nBASE_DATA[1]={X 1,Y 0,Z 0,A 0,B 0,C 0}\nPTP XH\n"
        "$BASE = BASE_DATA[1]\nPTP XH\nEND\n"
    )
    (target,) = krl.read(tmp_path / "h.src").targets
    assert target.used == (3, 5) and target.note == ""
