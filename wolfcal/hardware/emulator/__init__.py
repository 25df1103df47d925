"""A Dynamixel Protocol 2.0 servo bus on a pseudo-terminal, for dry runs and tests without a robot.

Each servo reports what a real one with a miscalibrated encoder would; with torque off an emulated operator
(optional) moves the limp joints through a list of poses (manual capture); faults make servos misbehave. The SDK
busy-waits holding the GIL, so the emulator runs in its own process (`EmulatorProcess`, or `wolfcal emulate`)
and publishes the true joint angles for the simulated camera.

Modules, one job each:
- `servo`: one servo: its control table and how its true angle moves;
- `imu`: the IMU as a device on the bus (`imu.bus`): gravity in its frame from the true angles, mount and bias;
- `faults`: the --fault syntax, what each fault does to a servo, when it starts;
- `emulated_operator`: the operator of manual capture, posing the limp joints;
- `spec`: what to emulate, from a robot config and a truth file;
- `instructions`: the servos' answers to instruction packets;
- `bus`: one emulated bus over time (servos, operator, faults, the IMU when on it; bytes in, bytes out);
- `true_state`: the true joint angles shared with the simulated camera;
- `serve`: the pty serving loop (a pty per bus of `servos.ports`, one process);
- `process`: the emulator in a process of its own.
The `wolfcal emulate` command is `wolfcal.capture.emulate` (it reads robot configs and poses files).
The names imported below are the package's public interface.
"""

from wolfcal.hardware.emulator.faults import Fault, parse_fault
from wolfcal.hardware.emulator.process import EmulatorProcess
from wolfcal.hardware.emulator.spec import EmulatorSpec, load_truth, spec_from_config
from wolfcal.hardware.emulator.true_state import read_true_angles, state_paths, truth_file_of

__all__ = [
    "EmulatorProcess",
    "EmulatorSpec",
    "Fault",
    "load_truth",
    "parse_fault",
    "read_true_angles",
    "truth_file_of",
    "spec_from_config",
    "state_paths",
]
