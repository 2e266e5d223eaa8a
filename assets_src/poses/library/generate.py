"""Writes the pose library's group files (alphabet, counting, everyday, rest, grips) from the short descriptions
below: `python assets_src/poses/library/generate.py`. The JSON files are what darthand reads and what is committed;
this script is how they were authored (edit here, run, commit both). grasps.json is the grasp stage's, not written
here; the 12 gestures of assets_src/poses join the library as the group 'gestures' through the loader.

Angles are degrees in model/anatomy's twist/spread/bend space (right hand; the left is its mirror). A finger is
(MCP bend, PIP bend, DIP bend, MCP spread); a thumb is (CMC twist, CMC spread, CMC bend, MCP bend, IP bend).
Positive spread moves a finger toward the little finger (for the thumb's CMC: toward the index finger).
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
FINGERS = ("index", "middle", "ring", "pinky")
LICENCE = "CC0-1.0"

# Fingers (MCP, PIP, DIP, spread)
EXT = (0, 0, 0, 0)
# Fist curls per finger (from assets_src/poses/fist.json)
CURL = {"index": (60, 75, 70, 0), "middle": (70, 90, 70, 0), "ring": (65, 80, 70, 0), "pinky": (55, 70, 70, 0)}
TIGHT = {"index": (80, 95, 70, 0), "middle": (85, 100, 70, 0), "ring": (85, 100, 70, 0), "pinky": (80, 95, 70, 0)}
HOOK = (10, 80, 60, 0)
HALF = (40, 50, 25, 0)
BENT = (80, 0, 0, 0)     # MCP only: a flat finger folded at the knuckle
RELAX = {"index": (12, 18, 8, 0), "middle": (16, 22, 10, 0), "ring": (20, 26, 12, 3), "pinky": (24, 30, 14, 6)}
FAN = {"index": -12, "middle": -3, "ring": 8, "pinky": 17}      # spread of an open, fanned hand
TOGETHER = {"index": 5, "middle": 1, "ring": -3, "pinky": -8}   # the rest pose's small fan closed

# Thumbs (CMC twist, spread, bend, MCP bend, IP bend)
T_FIST = (-39, 16, 47, 22, 59)      # across the curled middle finger (fist.json)
T_POINT = (-41, 17, 40, 19, 58)     # over the curled middle finger (point.json)
T_RING = (-1, 19, 16, 29, 75)       # over the curled ring finger (peace.json)
T_SIDE = (0, 18, 6, -1, 3)           # straight, against the side of the index (ASL A)
T_ACROSS = (-35, 28, 40, 25, 25)    # folded across the palm under straight fingers (ASL B, 4)
T_OUT = (0, -25, -10, 0, 0)         # abducted, straight (ASL L, Y)
T_UP = (-20, -30, -20, -10, -20)    # up and away from the fist (thumbs up)
T_REST = (0, 5, 10, 10, 10)
T_FLAT = (0, 0, 0, 0, 0)
T_OK = (0, 0, 12, 24, 20)           # tip to the bent index tip (ok.json)
T_C = (-15, -8, 15, 15, 15)         # curved, facing the curved fingers (ASL C)
T_UNDER = (-40, 28, 50, 35, 15)     # tucked under folded fingers (ASL M, N, T)


def scaled(f, s: float):
    """A finger or thumb tuple scaled by s (rounded to 0.1 degree)."""
    return tuple(round(v * s, 1) for v in f)


def blend(a, b, t: float):
    return tuple(round(x + t * (y - x), 1) for x, y in zip(a, b))


def hand(fingers: dict, thumb, spread: dict | None = None, twist: dict | None = None) -> dict:
    """The joints block: fingers {name: (mcp, pip, dip, spread)}, thumb (twist, spread, bend, mcp, ip)."""
    joints: dict = {}
    for name in FINGERS:
        mcp, pip, dip, sp = fingers[name]
        sp = sp + (spread or {}).get(name, 0)
        first = {"twist": (twist or {}).get(name, 0), "spread": sp, "bend": mcp}
        joints[f"{name}1"] = first
        joints[f"{name}2"] = {"bend": pip}
        joints[f"{name}3"] = {"bend": dip}
    tw, sp, b, mcp, ip = thumb
    joints["thumb1"] = {"twist": tw, "spread": sp, "bend": b}
    joints["thumb2"] = {"bend": mcp}
    joints["thumb3"] = {"bend": ip}
    return {k: {a: float(v) for a, v in d.items() if v != 0} for k, d in joints.items()
            if any(v != 0 for v in d.values())}


def fingers(**kw) -> dict:
    """Every finger curled as in a fist unless named: fingers(index=EXT) is a point's fingers."""
    return {f: kw.get(f, CURL[f]) for f in FINGERS}


def every(shape) -> dict:
    return {f: shape for f in FINGERS}


def pose(name, tags, description, joints, contacts=()):
    out = {"name": name, "tags": list(tags), "description": description, "joints": joints}
    if contacts:
        out["contacts"] = [list(c) for c in contacts]
    return out


# ------------------------------------------------------------------------------------------------ alphabet

def alphabet() -> list[dict]:
    v_spread = {"index": -10, "middle": 6}
    p = [
        pose("asl_a", ["fist", "thumb_side"], "A: a fist, the thumb straight against the side of the index.",
             hand(fingers(), T_SIDE)),
        pose("asl_b", ["flat", "thumb_across"], "B: four fingers straight and together, the thumb folded across "
             "the palm.", hand(every(EXT), T_ACROSS, spread=TOGETHER)),
        pose("asl_c", ["curved", "open"], "C: the fingers together and curved, the thumb curved below them: "
             "the letter's outline.", hand(every((25, 45, 30, 0)), T_C)),
        pose("asl_d", ["index", "ring_with_thumb"], "D: the index straight up, the other fingers curved to meet "
             "the thumb tip.", hand(fingers(index=EXT, middle=(45, 75, 40, 0), ring=(50, 75, 40, 0),
                                            pinky=(55, 70, 40, 0)), (-15, 10, 30, 25, 25)),
             contacts=[("thumb", "middle")]),
        pose("asl_e", ["curled", "thumb_across"], "E: the fingertips bent down to rest above the thumb, which is "
             "folded across the palm.", hand({"index": (40, 90, 77, 0), "middle": (43, 100, 80, 0),
                                                 "ring": (41, 93, 77, 0), "pinky": (37, 84, 72, 0)},
                                                (-29, 22, 56, 37, 39))),
        pose("asl_f", ["ok", "ring_with_thumb"], "F: index and thumb tips touch in a ring, the other three fingers "
             "straight and spread.", hand(fingers(index=(45, 60, 35, 0), middle=(0, 0, 0, -4), ring=(0, 0, 0, 6),
                                                  pinky=(0, 0, 0, 15)), T_OK), contacts=[("thumb", "index")]),
        pose("asl_g", ["index", "thumb_out"], "G: index and thumb straight and parallel, pointing sideways (the "
             "hand is turned; the shape is what is stored).", hand(fingers(index=EXT), (-20, 15, 0, 0, 0))),
        pose("asl_h", ["two_fingers", "together"], "H: index and middle straight and together, pointing sideways; "
             "the thumb over the ring finger.", hand(fingers(index=EXT, middle=EXT), T_RING,
                                                      spread={"index": 3, "middle": -3}),
             contacts=[("thumb", "ring")]),
        pose("asl_i", ["pinky"], "I: the little finger straight up, the others in a fist with the thumb across "
             "them.", hand(fingers(pinky=(0, 0, 0, 5)), T_FIST), contacts=[("thumb", "middle")]),
        pose("asl_j", ["pinky", "start_shape"], "J: its start shape (the letter traces a J with the little finger "
             "from here): as I.", hand(fingers(pinky=(0, 0, 0, 8)), T_FIST, spread={"pinky": 0}),
             contacts=[("thumb", "middle")]),
        pose("asl_k", ["two_fingers", "thumb_between"], "K: index up and middle forward in a V, the thumb between "
             "them at the middle finger.", hand(fingers(index=(0, 0, 0, -8), middle=(54, 5, 0, 4)),
                                                (-28, 29, 22, 23, 0)), contacts=[("thumb", "middle")]),
        pose("asl_l", ["index", "thumb_out"], "L: index straight up and thumb straight out: an L.",
             hand(fingers(index=EXT), T_OUT)),
        pose("asl_m", ["folded", "thumb_under"], "M: index, middle and ring folded over the thumb tucked under "
             "them.", hand(fingers(index=(64, 80, 38, 0), middle=(56, 91, 55, 0), ring=(70, 85, 40, 0),
                                   pinky=(57, 75, 59, 0)), (-35, 13, 59, 42, 19))),
        pose("asl_n", ["folded", "thumb_under"], "N: index and middle folded over the thumb tucked under them.",
             hand(fingers(index=(64, 80, 39, 0), middle=(70, 86, 40, 0), ring=(69, 81, 65, 0),
                          pinky=(60, 75, 55, 0)), (-36, 20, 45, 27, 15))),
        pose("asl_o", ["round", "ring_with_thumb"], "O: every fingertip meets the thumb tip in a round O.",
             hand(every((40, 55, 35, 0)), (-10, 5, 20, 28, 25), spread={"index": 2, "ring": -1, "pinky": -3}),
             contacts=[("thumb", "index"), ("thumb", "middle")]),
        pose("asl_p", ["two_fingers", "thumb_between"], "P: the K shape pointed down (the wrist turns; the hand "
             "shape is K's, the middle finger more forward).", hand(fingers(index=(10, 0, 0, -8),
                                                                         middle=(60, 10, 0, 4)),
                                                                 (-25, 22, 30, 15, 0)),
             contacts=[("thumb", "middle")]),
        pose("asl_q", ["index", "pincer"], "Q: thumb and index pointing down in a pincer (the G shape closing).",
             hand(fingers(index=(25, 20, 10, 0)), (-20, 10, 10, 10, 5))),
        pose("asl_r", ["crossed", "two_fingers"], "R: index and middle crossed, the middle over the index, as far as "
             "the rig's spread and twist limits allow.", hand(fingers(index=(5, 0, 0, 15), middle=(0, 0, 0, -15)),
                                                               T_RING, twist={"index": 10, "middle": -10}),
             contacts=[("thumb", "ring"), ("index", "middle")]),
        pose("asl_s", ["fist", "thumb_across"], "S: a fist, the thumb across the front of the fingers.",
             hand(fingers(), T_FIST), contacts=[("thumb", "middle")]),
        pose("asl_t", ["fist", "thumb_under"], "T: a fist, the thumb tip between index and middle under the "
             "index.", hand(fingers(index=(59, 86, 42, 0)), (-30, 20, 31, 22, 5))),
        pose("asl_u", ["two_fingers", "together"], "U: index and middle straight up and together, the thumb over "
             "the ring finger.", hand(fingers(index=EXT, middle=EXT), T_RING, spread={"index": 3, "middle": -3}),
             contacts=[("thumb", "ring")]),
        pose("asl_v", ["two_fingers", "spread"], "V: index and middle straight and apart, the thumb over the ring "
             "finger.", hand(fingers(index=EXT, middle=EXT), T_RING, spread=v_spread), contacts=[("thumb", "ring")]),
        pose("asl_w", ["three_fingers", "spread"], "W: index, middle and ring straight and apart, the thumb on the "
             "curled little finger.", hand(fingers(index=EXT, middle=EXT, ring=EXT, pinky=(59, 76, 53, 0)),
                                           (-16, 30, 52, 45, 40), spread={"index": -12, "ring": 8}),
             contacts=[("thumb", "pinky")]),
        pose("asl_x", ["hook", "index"], "X: the index hooked, the other fingers in a fist, the thumb over the "
             "middle.", hand(fingers(index=HOOK), T_POINT), contacts=[("thumb", "middle")]),
        pose("asl_y", ["thumb_out", "pinky"], "Y: thumb and little finger straight out, the other fingers curled.",
             hand(fingers(pinky=(0, 0, 0, 15)), T_OUT)),
        pose("asl_z", ["index", "start_shape"], "Z: its start shape (the index traces a Z from here): the index "
             "pointing, the others in a fist.", hand(fingers(index=(5, 0, 0, 0)), T_POINT),
             contacts=[("thumb", "middle")]),
    ]
    for q in p:
        q["tags"] = ["alphabet", "asl", f"letter_{q['name'][-1]}"] + q["tags"]
    return p


# ------------------------------------------------------------------------------------------------ counting

def counting() -> list[dict]:
    v = {"index": -10, "middle": 6}
    asl = [
        ("0", "zero: every fingertip meets the thumb in an O.",
         hand(every((40, 55, 35, 0)), (-10, 5, 20, 28, 25)), [("thumb", "index"), ("thumb", "middle")]),
        ("1", "one: the index up, the thumb over the curled middle.", hand(fingers(index=EXT), T_POINT),
         [("thumb", "middle")]),
        ("2", "two: index and middle up and apart.", hand(fingers(index=EXT, middle=EXT), T_RING, spread=v),
         [("thumb", "ring")]),
        ("3", "three: thumb, index and middle out.", hand(fingers(index=EXT, middle=EXT), T_OUT, spread=v), []),
        ("4", "four: four fingers up and apart, the thumb folded across the palm.",
         hand(every(EXT), T_ACROSS, spread=FAN), []),
        ("5", "five: every finger and the thumb spread.", hand(every(EXT), (0, -25, -15, 0, 0), spread=FAN), []),
        ("6", "six: the thumb tip on the little finger's tip, the other three up and apart.",
         hand(fingers(index=EXT, middle=EXT, ring=EXT, pinky=(55, 60, 35, 3)), (-12, 25, 54, 49, 30),
              spread={"index": -12, "ring": 8}), [("thumb", "pinky")]),
        ("7", "seven: the thumb tip on the ring finger's tip, the others up.",
         hand(fingers(index=EXT, middle=EXT, ring=(55, 60, 35, 0), pinky=(0, 0, 0, 15)), (-25, 10, 35, 30, 25),
              spread={"index": -12, "middle": -4}), [("thumb", "ring")]),
        ("8", "eight: the thumb tip on the middle finger's tip, the others up.",
         hand(fingers(index=EXT, middle=(50, 60, 35, 0), ring=(0, 0, 0, 6), pinky=(0, 0, 0, 15)),
              (-15, 8, 25, 28, 22), spread={"index": -12}), [("thumb", "middle")]),
        ("9", "nine: the thumb tip on the index tip, the others up (F's shape).",
         hand(fingers(index=(45, 60, 35, 0), middle=(0, 0, 0, -4), ring=(0, 0, 0, 6), pinky=(0, 0, 0, 15)), T_OK),
         [("thumb", "index")]),
        ("10", "ten: a fist with the thumb up (the number shakes it).", hand(fingers(), T_UP), []),
    ]
    out = [pose(f"asl_count_{n}", ["counting", "asl", f"number_{n}"], f"ASL {d}", j, c) for n, d, j, c in asl]
    eu = [
        ("0", "zero: a closed fist.", hand(fingers(), T_FIST), [("thumb", "middle")]),
        ("1", "one: the thumb up from a fist.", hand(fingers(), T_UP), []),
        ("2", "two: thumb and index out.", hand(fingers(index=EXT), T_OUT), []),
        ("3", "three: thumb, index and middle out.", hand(fingers(index=EXT, middle=EXT), T_OUT, spread=v), []),
        ("4", "four: thumb, index, middle and ring out, the little finger curled.",
         hand(fingers(index=EXT, middle=EXT, ring=EXT), T_OUT, spread={"index": -12, "ring": 8}), []),
        ("5", "five: the open hand.", hand(every(EXT), (0, -25, -15, 0, 0), spread=FAN), []),
    ]
    out += [pose(f"eu_count_{n}", ["counting", "european", f"number_{n}"], f"European (thumb first) {d}", j, c)
            for n, d, j, c in eu]
    cn = [
        ("6", "six: thumb and little finger out (as call-me).", hand(fingers(pinky=(0, 0, 0, 15)), T_OUT), []),
        ("7", "seven: the tips of thumb, index and middle together.",
         hand(fingers(index=(35, 45, 25, 2), middle=(35, 45, 25, -2)), (-15, 10, 25, 25, 20)),
         [("thumb", "index"), ("thumb", "middle")]),
        ("8", "eight: thumb and index out in an L.", hand(fingers(index=EXT), (0, -28, -15, 0, 0)), []),
        ("9", "nine: the index hooked, the others in a fist.", hand(fingers(index=(0, 85, 70, 0)), T_POINT),
         [("thumb", "middle")]),
        ("10", "ten: a fist (one of the hand signs of ten).", hand(fingers(), T_FIST), [("thumb", "middle")]),
    ]
    out += [pose(f"cn_count_{n}", ["counting", "chinese", f"number_{n}"], f"Chinese hand sign {d}", j, c)
            for n, d, j, c in cn]
    return out


# ------------------------------------------------------------------------------------------------ everyday gestures

def everyday() -> list[dict]:
    open_hand = hand(every(EXT), (0, -25, -15, 0, 0), spread=FAN)
    p = [
        pose("wave_open", ["wave", "open"], "A wave: the open hand, fingers fanned.", open_hand),
        pose("wave_relaxed", ["wave", "open", "relaxed"], "A relaxed wave: fingers slightly bent and apart.",
             hand(every((10, 12, 5, 0)), (0, -15, -5, 5, 5), spread={"index": -8, "ring": 5, "pinky": 12})),
        pose("wave_bye_fold", ["wave"], "Bye-bye: the four fingers folded down together at the knuckles.",
             hand(every((70, 15, 5, 0)), (0, -10, 0, 5, 5))),
        pose("point_index", ["point", "index"], "Pointing: the index straight, the others in a fist.",
             hand(fingers(index=EXT), T_POINT), [("thumb", "middle")]),
        pose("point_loose", ["point", "index", "relaxed"], "A loose point: the index straight, the others loosely "
             "curled, the thumb resting on the middle.", hand(fingers(index=(5, 5, 0, 0), middle=(50, 60, 40, 0),
                                                                      ring=(55, 65, 40, 0), pinky=(60, 65, 40, 0)),
                                                              (-25, 15, 30, 20, 30))),
        pose("point_thumb_out", ["point", "index"], "Pointing with the thumb out to the side.",
             hand(fingers(index=EXT), (0, -15, -5, 0, 0))),
        pose("thumbs_up_tight", ["thumbs_up", "approval"], "Thumbs up from a tight fist.", hand(TIGHT, T_UP)),
        pose("thumbs_down", ["thumbs_down", "disapproval"], "Thumbs down: the thumbs-up hand shape, turned over by "
             "the wrist.", hand(fingers(), (-25, -28, -15, -5, -10))),
        pose("ok_sign", ["ok", "ring_with_thumb"], "OK: thumb and index tips touching, the others fanned and "
             "slightly bent.", hand(fingers(index=(45, 60, 35, 0), middle=(8, 8, 3, -2), ring=(10, 10, 5, 6),
                                           pinky=(12, 12, 5, 14)), T_OK), [("thumb", "index")]),
        pose("peace_sign", ["peace", "two_fingers"], "Peace / victory: index and middle up in a V.",
             hand(fingers(index=EXT, middle=EXT), T_RING, spread={"index": -12, "middle": 8}), [("thumb", "ring")]),
        pose("peace_loose", ["peace", "two_fingers", "relaxed"], "A casual peace sign: the V slightly bent, the "
             "thumb resting on the ring finger.", hand(fingers(index=(8, 10, 5, 0), middle=(8, 10, 5, 0),
                                                              ring=(55, 70, 50, 0), pinky=(50, 65, 50, 0)),
                                                      (-5, 17, 18, 25, 60), spread={"index": -9, "middle": 5})),
        pose("rock_horns", ["rock", "horns"], "Horns: index and little finger up, the thumb over the middle.",
             hand(fingers(index=(0, 0, 0, -5), pinky=(0, 0, 0, 12)), T_POINT), [("thumb", "middle")]),
        pose("i_love_you", ["rock", "ily", "thumb_out"], "I love you (ASL): thumb, index and little finger out.",
             hand(fingers(index=(0, 0, 0, -8), pinky=(0, 0, 0, 15)), T_OUT)),
        pose("call_me", ["shaka", "thumb_out"], "Call me / shaka: thumb and little finger out, the others curled.",
             hand(fingers(pinky=(0, 0, 0, 18)), (0, -28, -15, 0, 0))),
        pose("stop_palm", ["stop", "flat"], "Stop: the flat hand, fingers together and straight, pushed back a "
             "little at the knuckles.", hand(every((-10, 0, 0, 0)), (0, 10, 0, 0, 0),
                                             spread={"index": 3, "pinky": -3})),
        pose("high_five", ["open", "spread"], "High five: the hand open and spread wide.",
             hand(every((-5, 0, 0, 0)), (0, -30, -15, -5, 0), spread={"index": -15, "middle": -4, "ring": 10,
                                                                      "pinky": 20})),
        pose("pinch_tips", ["pinch", "precision"], "A tip pinch: index and thumb tips together, the other fingers "
             "loosely straight.", hand(fingers(index=(40, 55, 30, 0), middle=(15, 15, 5, 0), ring=(15, 15, 5, 3),
                                              pinky=(18, 15, 5, 6)), (0, 2, 14, 25, 18)), [("thumb", "index")]),
        pose("pinch_pads", ["pinch", "precision"], "A pad pinch: index pad on the thumb pad, the fingers flat.",
             hand(fingers(index=(45, 35, 5, 0), middle=(10, 10, 5, 0), ring=(10, 10, 5, 0), pinky=(10, 10, 5, 0)),
                  (-5, 5, 20, 20, 0)), [("thumb", "index")]),
        pose("pinch_closed", ["pinch", "precision"], "A pinch with the other fingers curled into the palm.",
             hand(fingers(index=(40, 55, 30, 0), middle=(60, 70, 50, 0)), (0, 2, 14, 25, 18)),
             [("thumb", "index")]),
        pose("snap_start", ["snap", "start_shape"], "A finger snap's start: the middle fingertip pressed on the "
             "thumb pad, the index slightly bent, ring and little curled.",
             hand(fingers(index=(25, 30, 15, 0), middle=(45, 50, 25, 0), ring=(70, 85, 60, 0),
                          pinky=(65, 80, 60, 0)), (-20, 10, 25, 20, 10)), [("thumb", "middle")]),
        pose("beckon_index", ["beckon", "hook", "index"], "Come here: the index hooked, the others in a fist.",
             hand(fingers(index=(20, 80, 50, 0)), T_POINT), [("thumb", "middle")]),
        pose("beckon_hand", ["beckon"], "Come here with the whole hand: the fingers together, bent at the knuckles "
             "and middle joints.", hand(every((55, 45, 20, 0)), (0, 5, 10, 10, 10))),
        pose("fist_tight", ["fist", "power"], "A tight fist, the thumb across the fingers.", hand(TIGHT, T_FIST),
             [("thumb", "middle")]),
        pose("fist_loose", ["fist", "relaxed"], "A loose fist: fingers curled but not pressed, the thumb on the "
             "index.", hand({f: scaled(CURL[f], 0.75) for f in FINGERS}, (-30, 15, 30, 15, 30))),
        pose("fist_thumb_over_index", ["fist"], "A fist with the thumb pressed over the curled index.",
             hand(fingers(), (-23, 20, 30, 19, 35)), [("thumb", "index")]),
        pose("claw_open", ["claw", "open"], "A claw: fingers spread, hooked at the middle and end joints.",
             hand(every((15, 75, 60, 0)), (0, -10, 10, 20, 40), spread=FAN)),
        pose("claw_tight", ["claw"], "A tight claw: knuckles straight, fingers hooked hard.",
             hand(every((0, 95, 80, 0)), (-10, 10, 20, 30, 60), spread={"index": -5, "pinky": 5})),
        pose("finger_gun", ["gun", "index", "thumb_out"], "Finger gun: index straight, thumb up, the others "
             "curled.", hand(fingers(index=(3, 0, 0, 0)), (0, -22, -10, 0, 0))),
        pose("finger_gun_double", ["gun", "two_fingers", "thumb_out"], "A two-finger gun: index and middle "
             "together and straight, thumb up.", hand(fingers(index=EXT, middle=EXT), (0, -22, -10, 0, 0),
                                                       spread={"index": 3, "middle": -3})),
        pose("crossed_fingers", ["crossed", "luck"], "Fingers crossed: middle over index (as far as the rig's "
             "spread and twist limits let them cross), thumb over the ring.",
             hand(fingers(index=(10, 5, 0, 14), middle=(5, 5, 0, -14)), (-1, 20, 16, 31, 75),
                  twist={"index": 10, "middle": -10}),
             [("thumb", "ring"), ("index", "middle")]),
        pose("vulcan_salute", ["salute", "spread"], "Vulcan salute: index and middle together, ring and little "
             "together, a gap between middle and ring; the thumb out.",
             hand(every(EXT), (0, -25, -10, 0, 0), spread={"index": 2, "middle": -8, "ring": 10, "pinky": 4})),
        pose("pinky_promise", ["pinky", "hook"], "Pinky promise: the little finger hooked, the others in a fist.",
             hand(fingers(pinky=(20, 80, 50, 8)), T_FIST), [("thumb", "middle")]),
        pose("money_rub", ["money"], "Money: the thumb pad rubbing the index and middle tips.",
             hand(fingers(index=(45, 45, 20, 2), middle=(50, 50, 25, -2), ring=(60, 70, 50, 0),
                          pinky=(60, 70, 50, 0)), (-15, 10, 25, 20, 5)), [("thumb", "index")]),
        pose("fingertips_together", ["purse", "italian"], "All five fingertips together, pointing up (the Italian "
             "'what do you want').", hand(every((50, 45, 20, 0)), (-10, 8, 30, 25, 15),
                                          spread={"index": 4, "middle": 1, "ring": -2, "pinky": -6}),
             [("thumb", "index"), ("thumb", "middle")]),
        pose("finger_heart", ["heart"], "Finger heart: the thumb tip crossed over the bent index.",
             hand(fingers(index=(50, 60, 25, 0), middle=(75, 90, 60, 0)), (-20, 8, 25, 12, 10)),
             [("thumb", "index")]),
        pose("half_heart", ["heart", "curved"], "One hand's half of a heart: the fingers curved together, the "
             "thumb pointing down.", hand(every((45, 60, 25, 0)), (0, -10, -5, 0, 10),
                                          spread={"index": 2, "pinky": -3})),
        pose("air_quotes", ["quotes", "two_fingers", "hook"], "Air quotes: index and middle hooked, the others "
             "curled.", hand(fingers(index=(10, 60, 40, -5), middle=(10, 60, 40, 3)), T_RING, ),
             [("thumb", "ring")]),
        pose("rps_scissors", ["rock_paper_scissors", "two_fingers"], "Scissors: index and middle out and apart.",
             hand(fingers(index=EXT, middle=EXT), T_RING, spread={"index": -10, "middle": 8}), [("thumb", "ring")]),
        pose("rps_paper", ["rock_paper_scissors", "flat"], "Paper: the flat hand, fingers together.",
             hand(every(EXT), (0, 5, 0, 0, 0))),
        pose("rps_rock", ["rock_paper_scissors", "fist"], "Rock: a fist.", hand(fingers(), T_FIST),
             [("thumb", "middle")]),
        pose("middle_up_fold", ["count", "three_fingers"], "Middle three fingers up (a Scout's salute), thumb on "
             "the little finger.", hand(fingers(index=EXT, middle=EXT, ring=EXT, pinky=(59, 76, 53, 0)),
                                        (-16, 30, 52, 45, 40), spread={"index": 2, "ring": -2}),
             [("thumb", "pinky")]),
        pose("thumb_index_rub", ["money", "pinch"], "Thumb pad sliding on the index's side (the 'tiny amount').",
             hand(fingers(index=(35, 40, 20, 0), middle=(55, 70, 50, 0)), (-10, 20, 15, 10, 5)),
             [("thumb", "index")]),
        pose("pistol_grip_point", ["gun", "index"], "A pointing index with the thumb resting on its side.",
             hand(fingers(index=(5, 0, 0, 0)), T_SIDE)),
        pose("spock_palm", ["open", "flat"], "An open palm held up, fingers together, thumb alongside.",
             hand(every(EXT), (0, 12, 0, 0, 0), spread={"index": 3, "pinky": -3})),
        pose("clap_palm", ["flat", "relaxed"], "The clapping hand: flat, fingers slightly bent.",
             hand(every((8, 6, 2, 0)), (0, 0, 5, 5, 5))),
        pose("thumb_index_circle", ["ok", "ring_with_thumb"], "A small circle of thumb and index tips, the other "
             "fingers curled (the 'zero' or 'perfect' of some countries).", hand(fingers(index=(45, 60, 35, 0)), T_OK),
             [("thumb", "index")]),
        pose("thumbs_up_loose", ["thumbs_up", "approval", "relaxed"], "A casual thumbs up from a loose fist.",
             hand({f: scaled(CURL[f], 0.8) for f in FINGERS}, (-15, -25, -15, -5, -10))),
        pose("point_middle_knuckle", ["point", "index"], "Pointing with the index a little bent, as when "
             "indicating something near.", hand(fingers(index=(15, 15, 5, 0)), T_POINT), [("thumb", "middle")]),
        pose("wave_fingers_together", ["wave", "flat"], "A polite wave: the flat hand, fingers together.",
             hand(every((5, 3, 0, 0)), (0, 5, 0, 0, 0), spread=TOGETHER)),
    ]
    for q in p:
        q["tags"] = ["gesture"] + q["tags"]
    return p


# ------------------------------------------------------------------------------------------------ rest poses

def rest() -> list[dict]:
    p = [
        pose("rest_hanging", ["hanging"], "The hand hanging at the side: fingers curl more toward the little "
             "finger.", hand({"index": (15, 25, 10, 0), "middle": (20, 30, 12, 0), "ring": (25, 35, 14, 3),
                              "pinky": (30, 40, 16, 7)}, (0, 8, 15, 10, 15))),
        pose("rest_hanging_loose", ["hanging"], "A loosely hanging hand, a little more curled.",
             hand({"index": (22, 35, 15, 0), "middle": (27, 40, 18, 0), "ring": (32, 45, 20, 3),
                   "pinky": (37, 50, 22, 7)}, (-5, 10, 18, 12, 18))),
        pose("rest_table_flat", ["table"], "Resting palm down on a table: nearly flat, the fingertips touching it.",
             hand(every((5, 10, 5, 0)), (0, -5, 0, 5, 5), spread={"index": -4, "ring": 3, "pinky": 6})),
        pose("rest_table_arched", ["table"], "Palm down on a table, the knuckles raised a little (fingers arched).",
             hand(every((25, 25, 10, 0)), (0, -5, 5, 10, 10), spread={"index": -3, "ring": 2, "pinky": 5})),
        pose("rest_table_edge", ["table"], "The hand on its side on a table: fingers lightly curled.",
             hand({"index": (20, 30, 10, 0), "middle": (25, 35, 12, 0), "ring": (30, 38, 14, 0),
                   "pinky": (32, 40, 15, 0)}, (-5, 10, 15, 10, 10))),
        pose("rest_palm_up", ["lap", "palm_up"], "Palm up on the lap: fingers relaxed and curled.",
             hand({"index": (25, 40, 15, 0), "middle": (30, 45, 18, 0), "ring": (35, 50, 20, 3),
                   "pinky": (40, 55, 22, 6)}, (0, 5, 15, 15, 20))),
        pose("rest_sleeping", ["sleep", "curled"], "A sleeping hand: the fingers half curled.",
             hand({"index": (35, 50, 25, 0), "middle": (40, 55, 28, 0), "ring": (45, 60, 30, 2),
                   "pinky": (48, 60, 30, 5)}, (-10, 10, 20, 20, 25))),
        pose("rest_typing", ["keyboard"], "Home row on a keyboard: fingers curved, tips down.",
             hand(every((30, 50, 20, 0)), (0, 0, 10, 10, 5), spread={"index": -3, "ring": 2, "pinky": 5})),
        pose("rest_mouse", ["mouse"], "On a computer mouse: the fingers gently curved over it, the thumb at its "
             "side.", hand({"index": (15, 25, 10, 0), "middle": (18, 25, 10, 0), "ring": (25, 35, 15, 3),
                            "pinky": (30, 40, 18, 6)}, (0, -5, 15, 10, 5))),
        pose("rest_chin", ["fist", "relaxed"], "A relaxed fist, as under the chin.",
             hand({f: scaled(CURL[f], 0.6) for f in FINGERS}, (-25, 12, 25, 15, 20))),
        pose("rest_cupped", ["cupped"], "Cupped to hold water: fingers together, slightly bent, the thumb against "
             "the index.", hand(every((20, 20, 10, 0)), (0, 15, 10, 5, 5), spread={"index": 3, "pinky": -3})),
        pose("rest_flat_together", ["flat"], "Flat, fingers together.", hand(every(EXT), T_FLAT,
                                                                               spread={"index": 3, "pinky": -3})),
        pose("rest_flat_apart", ["flat", "spread"], "Flat, fingers a little apart.",
             hand(every(EXT), (0, -10, -5, 0, 0), spread={"index": -6, "middle": -1, "ring": 4, "pinky": 8})),
        pose("rest_thumb_tucked", ["relaxed"], "Relaxed, the thumb tucked to the palm's side.",
             hand(RELAX, (-20, 20, 20, 15, 15))),
        pose("rest_pocket", ["relaxed", "curled"], "As in a pocket: fingers half bent, together.",
             hand(every((40, 45, 20, 0)), (0, 10, 10, 10, 10), spread={"index": 2, "pinky": -3})),
        pose("rest_fingers_drape", ["hanging", "relaxed"], "Draped over an armrest: fingers bent at the "
             "knuckles, the rest loose.", hand(every((45, 20, 10, 0)), (0, 5, 15, 10, 10),
                                                spread={"index": -2, "ring": 2, "pinky": 5})),
        pose("rest_thumb_in_palm", ["relaxed", "curled"], "A relaxed hand with the thumb resting in the palm.",
             hand({f: scaled(CURL[f], 0.45) for f in FINGERS}, (-35, 25, 40, 20, 20))),
        pose("rest_holding_nothing", ["relaxed"], "The relaxed pose of an empty hand at a desk.",
             hand({"index": (18, 25, 10, 0), "middle": (22, 30, 12, 0), "ring": (26, 34, 14, 2),
                   "pinky": (30, 38, 16, 5)}, (0, 5, 12, 10, 10))),
    ]
    flat_thumb = T_REST
    for k, t in enumerate((0.15, 0.3, 0.45, 0.6, 0.75)):
        fing = {f: blend((0, 0, 0, FAN[f] * 0.4), CURL[f], t) for f in FINGERS}
        p.append(pose(f"rest_half_open_{k + 1}", ["half_open"], f"Between the open hand and a fist: {t:.0%} of "
                      "the fist's curl.", hand(fing, blend(flat_thumb, (-30, 15, 30, 15, 30), t))))
    for q in p:
        q["tags"] = ["rest"] + q["tags"]
    return p


# ------------------------------------------------------------------------------------------------ empty grips

def grips() -> list[dict]:
    p = [
        pose("grip_hook_bag", ["hook", "carry"], "Carrying a bag by its handles: knuckles straight, fingers hooked.",
             hand(every((10, 85, 55, 0)), (0, 5, 10, 10, 10))),
        pose("grip_cylinder_wide", ["wrap", "power"], "Around an unseen wide cylinder (a jar): fingers and thumb "
             "curved apart.", hand(every((30, 40, 25, 0)), (-20, -5, 20, 10, 10), spread={"index": -3, "pinky": 4})),
        pose("grip_cylinder_narrow", ["wrap", "power"], "Around an unseen broom handle: fingers curled, the thumb "
             "around.", hand(every((50, 70, 45, 0)), (-30, 10, 35, 20, 25))),
        pose("grip_pen", ["tripod", "precision", "writing"], "Holding an unseen pen: thumb, index and middle in a "
             "tripod, ring and little curled.", hand(fingers(index=(30, 35, 15, 0), middle=(40, 50, 20, 0),
                                                            ring=(55, 65, 40, 0), pinky=(60, 70, 40, 0)),
                                                    (-10, 10, 20, 15, 0)), [("thumb", "index")]),
        pose("grip_chopsticks", ["precision", "tripod"], "Chopsticks (unseen): index and middle extended a little, "
             "the thumb over them.", hand(fingers(index=(25, 25, 10, 0), middle=(35, 35, 15, 0),
                                                 ring=(55, 60, 35, 0), pinky=(60, 65, 35, 0)),
                                         (-15, 12, 20, 15, 5))),
        pose("grip_key", ["lateral", "pinch"], "Turning an unseen key: the thumb pad on the side of the curled "
             "index.", hand(fingers(index=(55, 60, 30, 0)), (-5, 12, 5, 5, 15)), [("thumb", "index")]),
        pose("grip_card", ["lateral", "precision"], "Holding an unseen card flat between thumb and the fingers' "
             "side.", hand(every((30, 20, 5, 0)), (-5, 25, 10, 5, 0), spread={"index": 2, "pinky": -2})),
        pose("grip_sphere", ["sphere", "power"], "Around an unseen ball: fingers spread and curved.",
             hand(every((35, 35, 25, 0)), (-20, -10, 25, 15, 10), spread=FAN)),
        pose("grip_disk", ["disk", "precision"], "Holding an unseen lid from above: fingers spread, tips down.",
             hand(every((35, 20, 10, 0)), (-20, -15, 20, 10, 5), spread=FAN)),
        pose("grip_trigger", ["tool", "power"], "A spray bottle's trigger: the index hooked forward, the others "
             "wrapped.", hand(fingers(index=(20, 50, 30, 0), middle=(60, 75, 50, 0), ring=(60, 75, 50, 0),
                                      pinky=(55, 70, 50, 0)), (-30, 10, 30, 20, 20))),
        pose("grip_phone", ["phone", "wrap"], "Holding an unseen phone: fingers curled around its back edge, the "
             "thumb free above its screen.", hand(every((45, 50, 30, 0)), (-10, -5, 15, 10, 5))),
        pose("grip_mug_handle", ["handle", "hook"], "An unseen mug's handle: index and middle through it, the "
             "thumb on top.", hand(fingers(index=(45, 80, 40, 0), middle=(50, 80, 40, 0), ring=(60, 85, 50, 0),
                                          pinky=(60, 80, 50, 0)), (-20, 20, 20, 10, 0))),
        pose("grip_tip_pinch_small", ["pinch", "precision"], "Picking up a small unseen bead: thumb and index tips "
             "almost touching.", hand(fingers(index=(40, 55, 35, 0), middle=(40, 55, 35, 0), ring=(45, 55, 35, 0),
                                              pinky=(45, 55, 35, 0)), (0, 2, 14, 25, 18)), [("thumb", "index")]),
        pose("grip_lateral_thin", ["lateral", "pinch"], "Pinching an unseen thin sheet between the thumb and "
             "the side of the index.", hand(fingers(index=(30, 30, 15, 0), middle=(45, 50, 30, 0),
                                                   ring=(50, 55, 30, 0), pinky=(55, 60, 30, 0)),
                                           (-10, 25, 10, 0, 0))),
    ]
    for q in p:
        q["tags"] = ["grip", "empty_handed"] + q["tags"]
    return p


GROUPS = {
    "alphabet": ("ASL fingerspelling: the 26 letters as static right-hand shapes (J and Z at their start shape; "
                 "letters that differ from another only by the wrist's orientation (G/Q, K/P, H/U) keep their "
                 "own hand shapes).", alphabet),
    "counting": ("Counting 0-10 by hand in three conventions: ASL numbers, European thumb-first counting and "
                 "Chinese hand signs for 6-10.", counting),
    "everyday": ("Everyday gestures: waves, points, thumbs, OK, peace, horns, call me, stop, pinches, snaps, "
                 "beckons, fists, claws, finger guns, crossed fingers and more.", everyday),
    "rest": ("Rest and relaxed poses: hanging, on a table, on a lap, half-open steps between open hand and fist.",
             rest),
    "grips": ("Empty-handed grips: how a hand holds things it is not holding (the grasp stage's grasps.json "
              "holds the taxonomy's pre-shapes).", grips),
}


def format_group(doc: dict) -> str:
    """The group as JSON with one line per pose field and per joint (readable, diffable)."""
    head = ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in doc.items() if k != "poses")
    poses = []
    for p in doc["poses"]:
        fields = [f"   {json.dumps(k)}: {json.dumps(v)}" for k, v in p.items() if k != "joints"]
        joints = ",\n".join(f"    {json.dumps(j)}: {json.dumps(a)}" for j, a in p["joints"].items())
        fields.append('   "joints": {\n' + joints + "\n   }")
        poses.append("  {\n" + ",\n".join(fields) + "\n  }")
    return "{\n" + head + ',\n "poses": [\n' + ",\n".join(poses) + "\n ]\n}\n"


def main() -> None:
    for group, (description, make) in GROUPS.items():
        doc = {"group": group, "description": description, "licence": LICENCE, "poses": make()}
        (HERE / f"{group}.json").write_text(format_group(doc))
        print(f"{group}: {len(doc['poses'])} poses")


if __name__ == "__main__":
    main()
