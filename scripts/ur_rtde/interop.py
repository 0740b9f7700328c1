"""Drive a UR controller (real or `cell virtual-ur`) with SDU ur_rtde and report what happened.

Runs RTDEReceiveInterface (all default variables), RTDEControlInterface (moveJ, moveL, async
moveL + stopL, servoJ, speedJ, stopScript) and RTDEIOInterface (standard digital out, speed slider) against
HOST and prints one JSON object per step on stdout. The Rust interop test checks the numbers.
Usage: python interop.py HOST
"""
import json
import sys
import time

import rtde_control
import rtde_io
import rtde_receive


def report(step, **values):
    print(json.dumps({"step": step, **values}), flush=True)


def main():
    host = sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1"
    receive = rtde_receive.RTDEReceiveInterface(host)
    time.sleep(0.1)
    report(
        "receive",
        connected=receive.isConnected(),
        q=receive.getActualQ(),
        tcp=receive.getActualTCPPose(),
        timestamp=receive.getTimestamp(),
        robot_mode=receive.getRobotMode(),
        safety_mode=receive.getSafetyMode(),
        runtime_state=receive.getRuntimeState(),
        target_q=receive.getTargetQ(),
        speed_scaling=receive.getSpeedScaling(),
        status_bits=receive.getRobotStatus(),
    )
    t0 = receive.getTimestamp()
    time.sleep(0.2)
    report("stream", elapsed=receive.getTimestamp() - t0)

    control = rtde_control.RTDEControlInterface(host)
    report("control_connected", connected=control.isConnected(), running=control.isProgramRunning())

    q_target = [0.3, -1.3, 1.4, -1.6, -1.5708, 0.2]
    ok = control.moveJ(q_target, 1.0, 2.0)
    time.sleep(0.05)  # let the receive interface's cached state catch up with the done signal
    report("moveJ", ok=ok, target=q_target, q=receive.getActualQ())

    start = receive.getActualTCPPose()
    pose_target = [start[0] + 0.05, start[1] - 0.03, start[2] + 0.04] + list(start[3:])
    ok = control.moveL(pose_target, 0.25, 1.0)
    time.sleep(0.05)
    report("moveL", ok=ok, target=pose_target, tcp=receive.getActualTCPPose())

    far = [pose_target[0], pose_target[1], pose_target[2] - 0.2] + list(pose_target[3:])
    control.moveL(far, 0.1, 0.5, True)
    time.sleep(0.5)
    before_stop = receive.getActualTCPPose()
    control.stopL(2.0)
    time.sleep(0.1)
    after_stop = receive.getActualTCPPose()
    time.sleep(0.3)
    report(
        "stopL",
        before=before_stop,
        after=after_stop,
        later=receive.getActualTCPPose(),
        speed=receive.getActualTCPSpeed(),
        far=far,
    )

    # servoJ: stream joint targets at 500 Hz, then servoStop.
    q0 = receive.getActualQ()
    q = list(q0)
    for i in range(1, 201):
        t = control.initPeriod()
        q = [q0[0] + 0.0005 * i] + list(q0[1:])
        control.servoJ(q, 0.0, 0.0, 0.002, 0.1, 300)
        # ur_rtde's own pacing: a steady 500 Hz stream, where time.sleep drifts and stalls.
        control.waitPeriod(t)
    control.servoStop(4.0)
    time.sleep(0.2)
    report("servoJ", start=q0, last_target=q, q=receive.getActualQ())

    # speedJ: joint 1 at 0.2 rad/s for 0.5 s, then speedStop.
    before = receive.getActualQ()
    control.speedJ([0.2, 0, 0, 0, 0, 0], 1.0, 0.002)
    time.sleep(0.5)
    control.speedStop(10.0)
    time.sleep(0.2)
    report("speedJ", before=before, after=receive.getActualQ(), qd=receive.getActualQd())

    control.stopScript()
    time.sleep(0.1)
    report("stopScript", runtime_state=receive.getRuntimeState())
    control.disconnect()

    io = rtde_io.RTDEIOInterface(host)
    ok_do = io.setStandardDigitalOut(7, True)
    ok_tool = io.setToolDigitalOut(0, True)
    ok_slider = io.setSpeedSlider(0.5)
    time.sleep(0.1)
    report(
        "io",
        ok=[ok_do, ok_tool, ok_slider],
        do7=receive.getDigitalOutState(7),
        do6=receive.getDigitalOutState(6),
        tool0=receive.getDigitalOutState(16),
        bits=receive.getActualDigitalOutputBits(),
        speed_fraction=receive.getTargetSpeedFraction(),
    )
    io.disconnect()
    receive.disconnect()


if __name__ == "__main__":
    main()
