"""
H-bridge drive rules: from a duty to the levels of a motor driver's inputs (no hardware).

The hardware layer (hardware_esp32.py) writes what these functions return to the
pins; keeping the rules here lets them run, and be tested, anywhere. Duties are raw
protocol units: -10000 .. 10000 (full PWM backward .. forward); PWM levels are
MicroPython's duty_u16 (0 .. 65535). Sign-magnitude drive with fast decay.

Drivers:

* ``TB6612`` (TB6612FNG) and ``L298N``: one PWM pin (PWMx / ENx) and two direction
  pins (xIN1, xIN2) per motor. Zero duty brakes (IN1 = IN2 = 1, PWM on) or coasts
  (IN1 = IN2 = 0).
* ``DRV8833``: two inputs per motor, both PWM. Zero duty brakes (both high) or coasts
  (both low).
* ``PWM_DIR`` (Cytron MDD10A, MD10C and the like): one PWM pin and one direction pin
  per motor. DIR high turns the motor forward as wired; zero duty is PWM off, which
  these drivers turn into a brake (BRAKE_AT_ZERO cannot make them coast).
"""

DRIVERS = ('TB6612', 'L298N', 'DRV8833', 'PWM_DIR')
DUTY_SCALE = 10000
PWM_FULL = 65535


def pwm_level(duty):
    """Return the duty_u16 level (0 .. 65535) of a raw duty's magnitude."""
    magnitude = -duty if duty < 0 else duty
    if magnitude >= DUTY_SCALE:
        return PWM_FULL
    return magnitude * PWM_FULL // DUTY_SCALE


def direction_pins_outputs(duty, brake):
    """
    TB6612 / L298N: return (pwm duty_u16, in1, in2) for a raw duty.

    Positive duty: IN1 high, IN2 low. Zero: brake (both high, PWM full) or coast
    (both low, PWM off).
    """
    if duty > 0:
        return pwm_level(duty), 1, 0
    if duty < 0:
        return pwm_level(duty), 0, 1
    if brake:
        return PWM_FULL, 1, 1
    return 0, 0, 0


def pwm_dir_outputs(duty):
    """
    PWM_DIR: return (pwm duty_u16, dir) for a raw duty.

    Positive duty: DIR high; negative: DIR low; zero: PWM off, DIR low.
    """
    if duty > 0:
        return pwm_level(duty), 1
    if duty < 0:
        return pwm_level(duty), 0
    return 0, 0


def two_pwm_outputs(duty, brake):
    """
    DRV8833: return (in1 duty_u16, in2 duty_u16) for a raw duty (fast decay).

    Positive duty: IN1 is the PWM, IN2 low. Zero: brake (both full) or coast (both off).
    """
    if duty > 0:
        return pwm_level(duty), 0
    if duty < 0:
        return 0, pwm_level(duty)
    if brake:
        return PWM_FULL, PWM_FULL
    return 0, 0
