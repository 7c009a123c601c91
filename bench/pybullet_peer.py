#!/usr/bin/env python3
"""PyBullet peer for equiarm_sim's step+render benchmark: a BulletArm-like close-loop env step.

What one step does (as BulletArm's CloseLoopEnv.step with a Kuka, docs/paper.md §3.2):
  * physics: dt 1/240, 50 solver iterations, gravity -10; Kuka iiwa with gripper
    (pybullet_data kuka_iiwa/kuka_with_gripper2.sdf, base at (-0.2, 0, 0)), the plane, one 5 cm cube
    loaded from the repository's urdf/cube.urdf;
  * moveTo: IK to the target (delta action clipped to 5 cm, workspace-clamped), joint position control
    (force 200, position gain 0.02, velocity gain 1), step until the joints are within 1e-3, stall for
    5 iterations, or 100 iterations; repeat IK up to 10 times until the end effector is within 1e-3 m;
  * gripper: finger targets p*0.2 rad, force 2, step until converged / stalled / 100 iterations;
  * render: getCameraImage at 152x152 with ER_TINY_RENDERER, called twice (RGB, then depth), as
    BulletArm's camera_side_rgbd does; camera eye (1, 0, 0.6), target (0.45, 0, 0), up (-1, 0, 0),
    fov 40, near 0.1, far 3.

--mode fixed (a conservative lower bound of the above): one IK solve, the finger
command, and exactly 100 physics steps; then the same two renders.

--mode floating (the cheapest PyBullet step we could call BulletArm-like): no arm; the repository's
urdf/gripper.urdf driven by a fixed constraint moved linearly over 24 physics steps at the paper's dt
(1/240 s, 50 solver iterations), fingers position-controlled; then the same two renders.

Prints one JSON line: {"steps", "median_ms", "p95_ms", "physics_median_ms", "render_median_ms"}.

    pip install pybullet
    python3 bench/pybullet_peer.py --steps 200 --seed 0
"""
import argparse
import json
import math
import os
import random
import time

import pybullet as p
import pybullet_data

WS = [(0.25, 0.65), (-0.2, 0.2), (0.01, 0.25)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--size", type=int, default=152)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mode", choices=["bulletarm", "fixed", "floating"], default="bulletarm")
    args = ap.parse_args()
    rng = random.Random(args.seed)

    p.connect(p.DIRECT)
    p.setAdditionalSearchPath(pybullet_data.getDataPath())
    p.setTimeStep(1.0 / 240.0)
    p.setPhysicsEngineParameter(numSolverIterations=50, numSubSteps=0)
    p.setGravity(0, 0, -10)
    p.loadURDF("plane.urdf")
    urdf_dir = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "urdf")
    if args.mode == "floating":
        gripper = p.loadURDF(os.path.join(urdf_dir, "gripper.urdf"), [0.45, 0, 0.255])
        cid = p.createConstraint(gripper, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0], [0.45, 0, 0.255])
        kuka = None
    else:
        kuka = p.loadSDF("kuka_iiwa/kuka_with_gripper2.sdf")[0]
        p.resetBasePositionAndOrientation(kuka, [-0.2, 0, 0], [0, 0, 0, 1])
    p.loadURDF(os.path.join(urdf_dir, "cube.urdf"), [0.5, 0.05, 0.025])
    arm = list(range(7))
    ee_link = 7
    fingers = [8, 11]

    view = p.computeViewMatrix([1.0, 0.0, 0.6], [0.45, 0.0, 0.0], [-1.0, 0.0, 0.0])
    proj = p.computeProjectionMatrixFOV(40.0, 1.0, 0.1, 3.0)

    def joint_positions(ids):
        return [s[0] for s in p.getJointStates(kuka, ids)]

    def move_to(pos, yaw):
        orn = p.getQuaternionFromEuler([math.pi, 0, yaw])
        for _ in range(10):
            q = p.calculateInverseKinematics(kuka, ee_link, pos, orn)[:7]
            p.setJointMotorControlArray(kuka, arm, p.POSITION_CONTROL, targetPositions=q,
                                        forces=[200] * 7, positionGains=[0.02] * 7,
                                        velocityGains=[1.0] * 7)
            prev, stall = None, 0
            for _ in range(100):
                p.stepSimulation()
                cur = joint_positions(arm)
                if max(abs(a - b) for a, b in zip(cur, q)) < 1e-3:
                    break
                if prev is not None and max(abs(a - b) for a, b in zip(cur, prev)) < 1e-4:
                    stall += 1
                    if stall >= 5:
                        break
                prev = cur
            ee = p.getLinkState(kuka, ee_link)[4]
            if max(abs(a - b) for a, b in zip(ee, pos)) < 1e-3:
                break

    def grip(open_ratio):
        target = open_ratio * 0.2
        p.setJointMotorControlArray(kuka, fingers, p.POSITION_CONTROL,
                                    targetPositions=[-target, target], forces=[2, 2])
        prev = None
        for _ in range(100):
            p.stepSimulation()
            cur = joint_positions(fingers)
            if abs(cur[0] + target) + abs(cur[1] - target) < 1e-3:
                break
            if prev is not None and abs(cur[0] - prev[0]) + abs(cur[1] - prev[1]) < 1e-4:
                break
            prev = cur

    pos = [0.45, 0.0, 0.20]
    yaw = 0.0
    if kuka is not None:
        move_to(pos, yaw)
    totals, physics, render = [], [], []
    for _ in range(args.steps):
        d = [rng.uniform(-0.05, 0.05) for _ in range(3)]
        pos = [min(max(pos[i] + d[i], WS[i][0]), WS[i][1]) for i in range(3)]
        yaw = min(max(yaw + rng.uniform(-math.pi / 4, math.pi / 4), -math.pi / 2), math.pi / 2)
        open_ratio = rng.choice([0.0, 1.0])
        t0 = time.perf_counter()
        if args.mode == "bulletarm":
            move_to(pos, yaw)
            grip(open_ratio)
        elif args.mode == "floating":
            start = p.getBasePositionAndOrientation(gripper)[0]
            goal = [pos[0], pos[1], pos[2] + 0.055]
            p.setJointMotorControlArray(gripper, [0, 1], p.POSITION_CONTROL,
                                        targetPositions=[open_ratio * 0.0375] * 2, forces=[20, 20])
            orn = p.getQuaternionFromEuler([0, 0, yaw])
            for k in range(1, 25):
                s_ = k / 24.0
                p.changeConstraint(cid, [start[i] + (goal[i] - start[i]) * s_ for i in range(3)], orn,
                                   maxForce=500)
                p.stepSimulation()
        else:
            orn = p.getQuaternionFromEuler([math.pi, 0, yaw])
            q = p.calculateInverseKinematics(kuka, ee_link, pos, orn)[:7]
            p.setJointMotorControlArray(kuka, arm, p.POSITION_CONTROL, targetPositions=q,
                                        forces=[200] * 7, positionGains=[0.02] * 7,
                                        velocityGains=[1.0] * 7)
            target = open_ratio * 0.2
            p.setJointMotorControlArray(kuka, fingers, p.POSITION_CONTROL,
                                        targetPositions=[-target, target], forces=[2, 2])
            for _ in range(100):
                p.stepSimulation()
        t1 = time.perf_counter()
        p.getCameraImage(args.size, args.size, view, proj, renderer=p.ER_TINY_RENDERER)  # RGB
        p.getCameraImage(args.size, args.size, view, proj, renderer=p.ER_TINY_RENDERER)  # depth
        t2 = time.perf_counter()
        totals.append((t2 - t0) * 1e3)
        physics.append((t1 - t0) * 1e3)
        render.append((t2 - t1) * 1e3)

    def pct(xs, q):
        s = sorted(xs)
        return s[min(len(s) - 1, int(q * (len(s) - 1) + 0.5))]

    print(json.dumps({
        "mode": args.mode,
        "steps": args.steps,
        "median_ms": pct(totals, 0.5),
        "p95_ms": pct(totals, 0.95),
        "physics_median_ms": pct(physics, 0.5),
        "render_median_ms": pct(render, 0.5),
    }))


if __name__ == "__main__":
    main()
