#!/usr/bin/env python3
"""Score the third world (third/score.py, frozen) with issue 52's "ambiguous".

    python3 desktop/bench/worlds/score_ambiguous.py --cases DIR [score.py's flags]

third/score.py was frozen before `ambiguous` existed: it reads an answer
that names nothing as honest or missed by `untestable` alone. This runs it
unchanged with one rule added in front of its `classify`: on an effect case
an ambiguous answer (`ambiguous` non-empty, no `effects`) is honest when an
entry's head word is among the truth's accepted names, wrong otherwise (the
named column shows `ambiguous: a/b`); on a clean case it is a false alarm.
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "third"))
import score  # noqa: E402

_classify = score.classify


def classify(d, truth):
    amb = d.get("ambiguous") or []
    if amb and not d.get("effects"):
        named = "ambiguous: " + "/".join(amb)
        if truth["clean"]:
            return "false_alarm", named
        hit = any(score.first_token(a) in truth["accept"] for a in amb)
        return ("honest" if hit else "wrong"), named
    return _classify(d, truth)


score.classify = classify

if __name__ == "__main__":
    score.main()
