"""Runs the peer benchmark's dam break in SPlisHSPlasH (PyPI wheel
`pysplishsplash`) and prints one JSON line with what it measured.

Called by the `bench-peers` binary (bench/peers/src/main.rs), which sets
OMP_NUM_THREADS to the thread count. The scene is written here from the
same parameters the binary gives meshless and salva3d: DFSPH, cubic spline
kernel and gradient, particle radius = spacing / 2 (SPlisHSPlasH's support
radius is 4 r = 2 spacing), a fixed time step (CFL off), the density and
divergence tolerances in percent, no viscosity, no XSPH, and the domain box
as a wall.

Timed (wall clock and process CPU time): only the steps after the warm-up,
from the return of one step callback to the next call. After each timed
step (outside the timing) it reads the particle densities, which
SPlisHSPlasH computes at the start of a step, that is at the positions the
previous step ended on, and the fluid-fluid neighbour counts of the same
search.
"""

import argparse
import json
import os
import shutil
import sys
import tempfile
import time

import numpy as np
import pysplishsplash as sph

# SPlisHSPlasH's enumerations (scene file keys, see its documentation).
DFSPH = 4
CUBIC = 0
BOUNDARY = {"particles": 0, "volume-maps": 2}


def scene(args):
    lo, hi = np.array(args.domain_min), np.array(args.domain_max)
    r = args.spacing / 2.0
    return {
        "Configuration": {
            "particleRadius": r,
            "simulationMethod": DFSPH,
            "gravitation": [0.0, -9.81, 0.0],
            "timeStepSize": args.dt,
            "cflMethod": 0,
            # The run stops once time exceeds stopAt: after warm-up + steps.
            "stopAt": (args.warmup + args.steps - 0.5) * args.dt,
            "enableZSort": True,
            "kernel": CUBIC,
            "gradKernel": CUBIC,
            "boundaryHandlingMethod": BOUNDARY[args.boundary],
            "enablePartioExport": False,
            "enableVTKExport": False,
            "DFSPH": {
                "maxIterations": args.max_iterations,
                "maxError": 100.0 * args.tolerance,
                "maxIterationsV": args.max_iterations,
                "maxErrorV": 100.0 * args.divergence_tolerance,
                "enableDivergenceSolver": True,
            },
        },
        "Materials": [
            {
                "id": "Fluid",
                "density0": args.rest_density,
                "viscosityMethod": 0,
                "xsphMethod": 0,
            }
        ],
        "RigidBodies": [
            {
                "geometryFile": os.path.abspath(args.box_obj),
                "translation": list((lo + hi) / 2.0),
                "scale": list(hi - lo),
                "isDynamic": False,
                "isWall": True,
                "mapInvert": True,
                "mapThickness": 0.0,
                "mapResolution": [int(round(x / (2 * args.spacing))) for x in hi - lo],
            }
        ],
        # SPlisHSPlasH's regular block puts its first particle one diameter
        # past `start`; widened by r on each side, the block holds the same
        # lattice as meshless's (centres from min + spacing / 2, spacing
        # apart).
        "FluidBlocks": [
            {
                "denseMode": 0,
                "start": list(np.array(args.column_min) - r),
                "end": list(np.array(args.column_max) + r),
            }
        ],
    }


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--spacing", type=float, required=True)
    p.add_argument("--dt", type=float, required=True)
    p.add_argument("--tolerance", type=float, required=True, help="fraction of rho_0")
    p.add_argument("--divergence-tolerance", type=float, required=True)
    p.add_argument("--max-iterations", type=int, default=100)
    p.add_argument("--rest-density", type=float, default=1000.0)
    p.add_argument("--warmup", type=int, required=True)
    p.add_argument("--steps", type=int, required=True)
    p.add_argument("--domain-min", type=float, nargs=3, required=True)
    p.add_argument("--domain-max", type=float, nargs=3, required=True)
    p.add_argument("--column-min", type=float, nargs=3, required=True)
    p.add_argument("--column-max", type=float, nargs=3, required=True)
    p.add_argument("--boundary", choices=sorted(BOUNDARY), default="particles")
    p.add_argument("--box-obj", required=True, help="the wheel's data/models/UnitBox.obj")
    args = p.parse_args()

    work = tempfile.mkdtemp(prefix="bench-peers-sph-")
    scene_file = os.path.join(work, "dam_break.json")
    with open(scene_file, "w") as f:
        json.dump(scene(args), f, indent=1)

    base = sph.Exec.SimulatorBase()
    base.init(
        sceneFile=scene_file,
        useCache=False,
        outputDir=os.path.join(work, "out"),
        initialPause=False,
        useGui=False,
    )
    sim_state = {}
    seconds, cpu, iterations, divergence_iterations, pairs, errors = 0.0, 0.0, 0, 0, 0, []
    means = []
    done = 0
    last, last_cpu = None, None

    def after_step():
        """SPlisHSPlasH calls this after every step; the step's time is the
        time since the previous call returned."""
        nonlocal seconds, cpu, iterations, divergence_iterations, pairs, done, last, last_cpu
        now, now_cpu = time.perf_counter(), time.process_time()
        done += 1
        if done > args.warmup:
            seconds += now - last
            cpu += now_cpu - last_cpu
            sim, fluid, solver, n, rho0 = sim_state["objects"]
            iterations += solver.getValueInt(sph.TimeStepDFSPH.SOLVER_ITERATIONS)
            divergence_iterations += solver.getValueInt(sph.TimeStepDFSPH.SOLVER_ITERATIONS_V)
            rho = np.asarray(fluid.getFieldBuffer("density"), dtype=np.float64)[:n]
            errors.append(float(np.mean(np.maximum(rho / rho0 - 1.0, 0.0))))
            means.append(float(np.mean(rho / rho0)))
            pairs += sum(sim.numberOfNeighbors(0, 0, i) for i in range(n))
        last, last_cpu = time.perf_counter(), time.process_time()

    def on_start():
        sim = sph.Simulation.getCurrent()
        fluid = sim.getFluidModel(0)
        sim_state["objects"] = (
            sim,
            fluid,
            sim.getTimeStep(),
            fluid.numActiveParticles(),
            fluid.getDensity0(),
        )

    base.setTimeStepCB(after_step)
    base.initSimulation()
    on_start()
    n = sim_state["objects"][3]
    x0 = np.asarray(sim_state["objects"][1].getFieldBuffer("position"), dtype=np.float64)
    x0 = x0.reshape(-1, 3)[:n]
    last, last_cpu = time.perf_counter(), time.process_time()
    base.runSimulation()
    print(
        json.dumps(
            {
                "particles": n,
                "steps": args.steps,
                "seconds": seconds,
                "cpu_seconds": cpu,
                "pressure_iterations": iterations,
                "divergence_iterations": divergence_iterations,
                "fluid_pairs": pairs,
                "density_error": float(np.mean(errors)),
                "mean_density": float(np.mean(means)),
                "time_step": sph.TimeManager.getCurrent().getTimeStepSize(),
                "column_min": x0.min(axis=0).tolist(),
                "column_max": x0.max(axis=0).tolist(),
            }
        )
    )
    sys.stdout.flush()
    base.cleanup()
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
