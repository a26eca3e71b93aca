"""Total reflection and transmission of a slab for a normally incident
collimated beam, by Prahl's adding-doubling method (iadpython, MIT): the
independent reference `physics/tests/transport.rs` holds the Monte Carlo
transport to where the slab's faces are mismatched.

    python3 scripts/adding_doubling_reference.py A B G N [QUAD ...]

A: single-scattering albedo mu_s / (mu_a + mu_s); B: optical thickness
(mu_a + mu_s) d; G: Henyey-Greenstein anisotropy; N: the slab's index,
in air on both sides (no slides). Prints one line per quadrature order:
`QUAD UR1 UT1`, where UR1 includes the front face's specular reflection
and UT1 the unscattered beam. Adding-doubling is deterministic; its
error is its quadrature's, which the spread over orders shows.
"""

import sys

import iadpython


def main() -> None:
    a, b, g, n = (float(v) for v in sys.argv[1:5])
    orders = [int(v) for v in sys.argv[5:]] or [16, 32]
    for q in orders:
        sample = iadpython.Sample(
            a=a, b=b, g=g, d=1.0, n=n, n_above=1.0, n_below=1.0, quad_pts=q
        )
        ur1, ut1, _, _ = sample.rt()
        print(f"{q} {float(ur1):.7f} {float(ut1):.7f}")


if __name__ == "__main__":
    main()
