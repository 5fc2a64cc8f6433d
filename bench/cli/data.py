"""``python -m bench data``: a simulated system's samples in the suite's CSV
format, with undeclared effects and noise where asked."""

from __future__ import annotations

from pathlib import Path

from bench.cli.parser import UsageError
from bench.cli.options import add_plugin, check_names, load_plugins
from bench.core.arguments import noise_level, positive, positive_int, seed
from bench.core.data import add_noise, generate
from bench.core.csv_format import write_csv
from bench.physics.effects import EFFECTS
from bench.core.fileio import check_output
from bench.physics.undeclared import GENERATOR_LAWS, add_effects, parse_effects
from systems import SYSTEMS


def add_arguments(d) -> None:
    d.add_argument("--system", required=True, help="a simulated system")
    d.add_argument("--n", type=positive_int, required=True, help="number of samples")
    d.add_argument("--seed", type=seed, required=True, help="the generator's seed (the same seed gives the same data)")
    d.add_argument("--out", type=Path, required=True, help="CSV file to write")
    d.add_argument("--domain-half-width", type=positive, default=None,
                   help="sample angles, velocities and accelerations from U(-w, w) (default: the system's own domain)")
    d.add_argument("--effects", nargs="+", default=[], metavar="NAME=c1,...,cn",
                   help="add effects the system does not declare: one coefficient per joint for "
                        f"{', '.join(n for n, e in EFFECTS.items() if e.arity == 1 and e.shaped is None)} "
                        "(e.g. viscous_friction=0.8,0.5); "
                        f"i-j:c items for {', '.join(n for n, e in EFFECTS.items() if e.arity == 2)} on the "
                        "difference of coordinates i and j (e.g. coupled_spring=1-2:3.0); "
                        + "; ".join(f"j:{','.join(law.parameters)} items for {name}" for name, law in GENERATOR_LAWS.items())
                        + ", ';'-separated (e.g. stribeck_friction=1:1.0,2.0,0.5,0.3); "
                        "one number for a planar chain's tip_payload (its mass) or gravity_tilt (radians)")
    d.add_argument("--noise", type=noise_level, default=0.0,
                   help="Gaussian noise on tau as a fraction of each joint's torque std (default 0)")
    add_plugin(d)


def main(args) -> int:
    check_output(args.out)
    (name,), _ = load_plugins(args, [args.system])
    check_names(args, systems=[name])
    cls = SYSTEMS[name]
    system = cls()
    if not system.simulated:
        raise UsageError(f"{name} is measured; its data come with the suite (python -m bench residual --system {name} ...)")
    if args.domain_half_width:
        system = cls(domain=system.scaled_domain(args.domain_half_width))
    effects = parse_effects(args.effects, system.dof) if args.effects else {}
    data = generate(system, args.n, args.seed)
    if effects:
        data = add_effects(data, effects, system)
    if args.noise:
        data = add_noise(data, "indirect", args.noise, args.seed)
    write_csv(data, args.out)
    extra = "".join([f", undeclared {', '.join(args.effects)}" if effects else "",
                     f", {args.noise:g} x std noise on tau" if args.noise else ""])
    print(f"wrote {len(data)} samples of {name} (seed {args.seed}{extra}) to {args.out}")
    return 0
