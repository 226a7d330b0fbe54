"""80-digit reference values for the NCP functions of crates/ncp (tests/it/ncp_functions.rs reads the output).

Independent of the Rust code: each function is evaluated from its definition as an expectation, in mpmath
with 50 significant digits, at double inputs (exact in mpmath), and rounded once to double.

    python3 tests/data/ncp_reference.py > tests/data/ncp_reference.json
"""
import json
import mpmath as mp

mp.mp.dps = 80


def logistic(a, b, s):
    # E[min(a, b_L)] = a - s log(1 + exp((a - b)/s)) (paper eq. 17), with derivatives.
    # Written as min(a, b) - s log(1 + exp(-|c|)), an exact identity: the literal form cancels beyond any
    # fixed precision when |c| is large (c reaches 1e20 here).
    c = (a - b) / s
    sp = mp.log1p(mp.exp(-abs(c)))
    sig = 1 / (1 + mp.exp(-c))
    return min(a, b) - s * sp, 1 / (1 + mp.exp(c)), sig


def normal_mean(a, b, s):
    # E[min(a, b + s Z)] = a - s^2 p(a) - (a - b) P(a) (paper footnote 3), p, P of N(b, s^2).
    # With p(a) = pdf(alpha) / s and P(a) = Phi(alpha); 1 - P as Phi(-alpha) to avoid cancellation.
    al = (a - b) / s
    P = mp.ncdf(al)
    pdf = mp.npdf(al)
    return a - s * pdf - (a - b) * P, mp.ncdf(-al), P


def normal_squared(a, b, s):
    # E[min(a, b + s Z)^2] by its defining integral split at a: int_{-inf}^{a} t^2 dN + a^2 P(b_N > a),
    # the Gaussian moments taken in closed form from mpmath's incomplete moments.
    al = (a - b) / s
    P = mp.ncdf(al)
    pdf = mp.npdf(al)
    # int_{-inf}^{al} (b + s z)^2 phi(z) dz = b^2 P - 2 b s pdf + s^2 (P - al pdf)
    low = b * b * P - 2 * b * s * pdf + s * s * (P - al * pdf)
    value = low + a * a * mp.ncdf(-al)
    da = 2 * a * mp.ncdf(-al)
    db = 2 * (b * P - s * pdf)
    return value, da, db


def logistic_squared(a, b, s):
    # E[min(a, b_L)^2] = a^2 - 2 a s log(1 + e^c) - 2 s^2 Li2(-e^c): the paper's footnote 3 with the sign of
    # the last term corrected (checked by quadrature in check_logistic_squared below). Literal form, so only
    # for |c| <= 700, where 80 digits absorb its cancellation.
    if abs((a - b) / s) > 700:
        return None
    # The literal form cancels about |c| / ln(10) digits: work with that many more (c included).
    with mp.workdps(80 + int(0.5 * abs((a - b) / s))):
        c = (a - b) / s
        value = a * a - 2 * a * s * mp.log1p(mp.exp(c)) - 2 * s * s * mp.polylog(2, -mp.exp(c))
        da = 2 * a / (1 + mp.exp(c))
        db = 2 * (a / (1 + mp.exp(-c)) - s * mp.log1p(mp.exp(c)))
        return +value, +da, +db


def check_logistic_squared():
    """The corrected footnote formula against quadrature of its definition; the printed sign fails."""
    for (a, b, s) in ((0.3, 0.1, 0.2), (-1.0, 0.5, 0.7), (2.0, -1.0, 1.5)):
        a, b, s = mp.mpf(a), mp.mpf(b), mp.mpf(s)
        dens = lambda x: 1 / (s * (mp.exp((x - b) / (2 * s)) + mp.exp((b - x) / (2 * s))) ** 2)
        with mp.workdps(30):
            quad = mp.quad(lambda x: min(a, x) ** 2 * dens(x), [-mp.inf, a, mp.inf])
        c = (a - b) / s
        printed = a * a - 2 * a * s * mp.log1p(mp.exp(c)) + 2 * s * s * mp.polylog(2, -mp.exp(c))
        assert abs(logistic_squared(a, b, s)[0] - quad) < 1e-20, (a, b, s)
        assert abs(printed - quad) > 1e-3, (a, b, s)


def fischer_burmeister(a, b):
    return a + b - mp.sqrt(a * a + b * b)


def main():
    mags = [0.0, 1e-8, 0.3, 1.0, 7.0, 1e3, 1e8]
    args = sorted(set([m for m in mags] + [-m for m in mags]))
    sigmas = [1e-12, 1e-6, 1e-3, 0.1, 1.0, 10.0, 1e3]
    rows = []
    for a in args:
        for b in args:
            A, B = mp.mpf(a), mp.mpf(b)
            fb = fischer_burmeister(A, B)
            for s in sigmas:
                S = mp.mpf(s)
                row = {"a": a, "b": b, "sigma": s}
                for name, f in (("logistic", logistic), ("normal", normal_mean), ("normal_squared", normal_squared)):
                    v, da, db = f(A, B, S)
                    row[name] = [float(v), float(da), float(db)]
                row["fischer_burmeister"] = float(fb)
                ls = logistic_squared(A, B, S)
                row["logistic_squared"] = None if ls is None else [float(v) for v in ls]
                rows.append(row)
    # A sweep through the middle of the normal tails, where the closed forms cancel (|a - b| / sigma in 1..12).
    for k in range(1, 120):
        al = 0.1 * k
        for (b, s) in ((0.0, 1.0), (2.5, 0.01), (-0.7, 0.3)):
            for sign in (1, -1):
                a = b + sign * al * s
                A, B, S = mp.mpf(a), mp.mpf(b), mp.mpf(s)
                row = {"a": a, "b": b, "sigma": s}
                for name, f in (("logistic", logistic), ("normal", normal_mean), ("normal_squared", normal_squared)):
                    v, da, db = f(A, B, S)
                    row[name] = [float(v), float(da), float(db)]
                row["fischer_burmeister"] = float(fischer_burmeister(A, B))
                ls = logistic_squared(A, B, S)
                row["logistic_squared"] = None if ls is None else [float(v) for v in ls]
                rows.append(row)
    json.dump({"generator": "tests/data/ncp_reference.py (mpmath, 80 digits)", "cases": rows}, __import__("sys").stdout)


check_logistic_squared()
main()
