"""Examples shown at the end of every command's --help (gpquad.cli.commands applies them)."""

EXAMPLES = {
    "simulate": [
        "gpquad simulate --out flight.csv",
        "gpquad simulate experiments/rigid_body.toml --out rigid.parquet",
    ],
    "fly": [
        "gpquad fly results/RUN --inputs sticks.csv --out flown.csv",
        "gpquad fly results/RUN --inputs sticks.csv --out flown.csv --initial 0.1,0,0,0,0,0,0,0,0",
    ],
    "bench": ["gpquad bench", "gpquad bench --full --json"],
    "data": ["gpquad data check flight.ulg", "gpquad data export flight.ulg --out flight.csv"],
    "data check": [
        "gpquad data check flight.ulg",
        "gpquad data check logs/S250 --config my.toml --plot s250.png",
    ],
    "data align": [
        "gpquad data align px4.ulg betaflight.bbl",
        "gpquad data align a.ulg b.ulg --signal p,q --max-lag 5",
    ],
    "data export": [
        "gpquad data export flight.ulg --out flight.csv",
        "gpquad data export flight.bbl --config my.toml --out flight.parquet",
    ],
    "baseline": [
        "gpquad baseline ga-gradient experiments/baseline_ga_gradient.toml",
        "gpquad baseline pem experiments/baseline_pem.toml --out results/pem",
    ],
    "compare": [
        "gpquad compare results/RUN_A results/RUN_B --horizon 175",
        "gpquad compare results/RUN_A results/PEM --data-from results/RUN_A",
    ],
    "sweep": [
        "gpquad sweep experiments/paper.toml --jobs 2",
        "gpquad sweep experiments/smoke.toml --jobs 2 --out results/smoke",
    ],
    "report": ["gpquad report results/paper-sweep-seed2011", "gpquad report results/RUN"],
    "score": [
        "gpquad score results/RUN --data other_flight.ulg",
        "gpquad score results/RUN --data flight.ulg --part validation --horizon-s 30",
    ],
    "control": ["gpquad control pid results/RUN", "gpquad control lq experiments/control.toml"],
    "control pid": [
        "gpquad control pid results/RUN",
        "gpquad control pid results/RUN --courses 8 --seed 2 --json",
    ],
    "control lq": ["gpquad control lq experiments/control.toml"],
    "physics": [
        "gpquad physics thrust experiments/physics_rotorpy.toml",
        "gpquad physics drag my_log_physics.toml --json",
    ],
    "physics mixer": ["gpquad physics mixer flight.bbl"],
    "physics thrust": [
        "gpquad physics thrust experiments/physics_rotorpy.toml",
        "gpquad physics thrust my_log_physics.toml --json",
    ],
    "physics drag": [
        "gpquad physics drag experiments/physics_rotorpy.toml",
        "gpquad physics drag my_log_physics.toml --json",
    ],
    "physics deadreckon": ["gpquad physics deadreckon experiments/physics_rotorpy.toml"],
    "benchmark": [
        "gpquad benchmark median px4-s250 --peers zero,sindy --seeds 1",
        "gpquad benchmark --jobs 2 --out results/benchmark",
    ],
}
