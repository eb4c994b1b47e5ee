"""The compiled inner loop of the simulated testbed: sensors, firmware control law and
plant for a batch of 1200 Hz control periods.

Written with numba because it must run far faster than real time (campaigns and tests
run the simulator as fast as possible) and the friction model makes the plant
nonlinear, so it cannot be vectorised over time; there is no library that runs an
uploaded SOS controller around a hysteretic plant.  Everything here is plain floats and
arrays; the Python side (engine.py) owns the arrays and interprets the results.

Order within one control period k (time t_k):
  1. sample the sensors (encoders, gyro with its delay, autocollimator), update the LOS
     estimate;  2. watchdog, profile sample;  3. control law -> u1, u2, saturation,
  anti-windup;  4. hold u over the period and integrate the plant in `substeps` exact
  ZOH steps, updating the Dahl friction torque after each.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .friction import friction_step

# --- firmware state vector indices (engine.py names them for Python) -------------------
FW_MODE, FW_ARMED, FW_FAULT, FW_COMP_ON, FW_REF, FW_I1, FW_I2 = 0, 1, 2, 3, 4, 5, 6
FW_PROF_ACTIVE, FW_PROF_POS, FW_PROF_TARGET, FW_LAST_HEARD, FW_TICK = 7, 8, 9, 10, 11
FW_LOS_EST, FW_PREV_ENC, FW_KP, FW_SAT1, FW_SAT2, FW_WD_TICKS, FW_SESSION = 12, 13, 14, 15, 16, 17, 18
FW_RATE_REF, FW_TRAVEL, FW_T_DAHL, FW_COMP_TORQUE, FW_ENC_INIT, FW_ENC_INNER = 19, 20, 21, 22, 23, 24
FW_ANTI_WINDUP = 25
FW_SIZE = 26

MODE_IDLE, MODE_OPEN_LOOP, MODE_RELATIVE, MODE_INERTIAL = 0, 1, 2, 3
TARGET_REFERENCE, TARGET_RATE_REFERENCE, TARGET_CURRENT_COARSE, TARGET_CURRENT_FINE = 0, 1, 2, 3
FAULT_NONE, FAULT_WATCHDOG, FAULT_OVER_TRAVEL, FAULT_FLEXURE = 0, 1, 2, 3
EV_WATCHDOG, EV_OVER_TRAVEL, EV_FLEXURE, EV_PROFILE_DONE = 1, 2, 3, 4

# --- sensor/plant constants vector indices ---------------------------------------------
K_ENC_LSB, K_BASE_LSB, K_GYRO_LSB, K_GYRO_RANGE, K_AC_LSB, K_ENC_NOISE, K_AC_NOISE = 0, 1, 2, 3, 4, 5, 6
K_GYRO_SIGMA, K_GYRO_BIAS, K_DELAY, K_COMP_ALPHA, K_INERTIAL, K_TWO_DOF, K_KT1, K_KT2 = 7, 8, 9, 10, 11, 12, 13, 14
K_R1, K_R2, K_KE1, K_KE2, K_DT, K_SUBSTEPS, K_LOS_IDX, K_FRICTION_MODEL = 15, 16, 17, 18, 19, 20, 21, 22
K_FLEX_SAFE, K_PEAK1, K_PEAK2 = 23, 24, 25
K_RIPPLE_AMP, K_RIPPLE_WAVENUMBER, K_RIPPLE_PHASE = 26, 27, 28
K_SIZE = 29

# --- output columns ----------------------------------------------------------------------
OUT_COLUMNS = ("mode", "armed", "coarse_saturated", "fine_saturated", "profile_active",
               "friction_comp_on", "fault", "encoder_outer", "encoder_inner", "encoder_base",
               "gyro_rate", "autocollimator", "los_estimate", "reference", "error_angle",
               "error_rate", "torque_coarse_cmd", "torque_fine_cmd", "current_coarse",
               "current_fine", "voltage_coarse", "voltage_fine", "friction_comp_torque",
               "profile_index")
TRUTH_COLUMNS = ("theta1", "theta2", "theta_base", "los_rate", "friction_torque", "deflection")
N_OUT = len(OUT_COLUMNS)
N_TRUTH = len(TRUTH_COLUMNS)
N_NOISE = 4


@njit(cache=True)
def sos_run(sos, z, z_new, x):
    """Direct-form II transposed cascade; writes the next state into z_new (commit is
    the caller's choice: anti-windup keeps the old state while saturated)."""
    y = x
    for i in range(sos.shape[0]):
        out = sos[i, 0] * y + z[i, 0]
        z_new[i, 0] = sos[i, 1] * y - sos[i, 4] * out + z[i, 1]
        z_new[i, 1] = sos[i, 2] * y - sos[i, 5] * out
        y = out
    return y


@njit(cache=True)
def _quantise(value, lsb):
    return np.floor(value / lsb + 0.5) * lsb


@njit(cache=True)
def _record(events, n_ev, tick, code):
    """Append (tick, code) to the batch's event list if there is room; new count."""
    if n_ev < events.shape[0]:
        events[n_ev, 0], events[n_ev, 1] = tick, code
        return n_ev + 1
    return n_ev


@njit(cache=True)
def _safe_state(fw):
    fw[FW_ARMED] = 0.0
    fw[FW_I1] = 0.0
    fw[FW_I2] = 0.0
    fw[FW_PROF_ACTIVE] = 0.0
    fw[FW_MODE] = MODE_IDLE


@njit(cache=True)
def run_ticks(n, x, Ad, Bd, k, fw, fstate, fstack, flut_x, flut_y, fparams,
              cstate, cstack, clut_x, clut_y, cparams, sos, zs, zs_new,
              gbuf, gpos, profile, noise, v_fg, out, truth, events):
    """Advance n control periods.  sos/zs/zs_new: (6, sections, 6|2) for relative c0 c1
    c2 then inertial c0 c1 c2.  fparams/cparams: [model, sigma, T_c, alpha] of the plant's
    and the compensator's friction.  gpos: 1-element int array.  Returns events written."""
    n_ev = 0
    nsub = int(k[K_SUBSTEPS])
    los_idx = int(k[K_LOS_IDX])
    glen = gbuf.shape[0]
    u = np.zeros(4)
    xn = np.empty_like(x)
    plant_model = int(fparams[0])
    comp_model = int(cparams[0])
    inertial = k[K_INERTIAL] > 0.5
    two_dof = k[K_TWO_DOF] > 0.5
    dt = k[K_DT]
    ripple_amp, ripple_k, ripple_phase = k[K_RIPPLE_AMP], k[K_RIPPLE_WAVENUMBER], k[K_RIPPLE_PHASE]
    for t in range(n):
        fw[FW_TICK] += 1.0
        tick = fw[FW_TICK]
        # ---- 1. sensors at the start of the period
        th1, thb = x[0], x[4]
        th2 = x[los_idx]
        enc_outer = _quantise(th1 - thb + k[K_ENC_NOISE] * noise[t, 0], k[K_ENC_LSB])
        if two_dof:
            enc_inner = _quantise(th2 - thb + k[K_ENC_NOISE] * noise[t, 1], k[K_ENC_LSB])
        else:
            enc_inner = enc_outer
        enc_base = _quantise(thb, k[K_BASE_LSB])
        fw[FW_ENC_INNER] = enc_inner
        gyro = 0.0
        ac = 0.0
        if inertial:
            d = k[K_DELAY]
            di = int(np.floor(d))
            frac = d - di
            newest = gpos[0] - 1
            a = gbuf[(newest - di) % glen]
            b = gbuf[(newest - di - 1) % glen]
            g = a + (b - a) * frac + k[K_GYRO_BIAS] + k[K_GYRO_SIGMA] * noise[t, 2]
            g = _quantise(g, k[K_GYRO_LSB])
            gyro = min(max(g, -k[K_GYRO_RANGE]), k[K_GYRO_RANGE])
            counts = np.floor((th2 + k[K_AC_NOISE] * noise[t, 3]) / k[K_AC_LSB] + 0.5)
            ac = min(max(counts, -32768.0), 32767.0) * k[K_AC_LSB]
            alpha = k[K_COMP_ALPHA]
            fw[FW_LOS_EST] = alpha * (fw[FW_LOS_EST] + gyro * dt) + (1.0 - alpha) * ac
        else:
            fw[FW_LOS_EST] = enc_inner
        los_est = fw[FW_LOS_EST]
        # ---- 2. watchdog and profile
        armed = fw[FW_ARMED] > 0.5
        if armed and fw[FW_SESSION] > 0.5 and tick - fw[FW_LAST_HEARD] > fw[FW_WD_TICKS]:
            _safe_state(fw)
            fw[FW_FAULT] = FAULT_WATCHDOG
            n_ev = _record(events, n_ev, tick, EV_WATCHDOG)
            armed = False
        played = 0.0
        if armed and fw[FW_PROF_ACTIVE] > 0.5:
            pos = int(fw[FW_PROF_POS])
            sample = profile[pos]
            fw[FW_PROF_POS] = pos + 1
            played = pos + 1.0
            target = int(fw[FW_PROF_TARGET])
            if target == TARGET_REFERENCE:
                fw[FW_REF] = sample
            elif target == TARGET_RATE_REFERENCE:
                fw[FW_RATE_REF] = sample
            elif target == TARGET_CURRENT_COARSE:
                fw[FW_I1] = sample
            else:
                fw[FW_I2] = sample
            if pos + 1 >= profile.shape[0]:
                fw[FW_PROF_ACTIVE] = 0.0
                n_ev = _record(events, n_ev, tick, EV_PROFILE_DONE)
        # ---- 3. control law (the compensator tracks the bearing even when disarmed)
        dphi_meas = enc_outer - fw[FW_PREV_ENC] if fw[FW_ENC_INIT] > 0.5 else 0.0
        fw[FW_PREV_ENC] = enc_outer
        fw[FW_ENC_INIT] = 1.0
        t_comp = friction_step(cstate, cstack, dphi_meas, dphi_meas, comp_model,
                               cparams[1], cparams[2], cparams[3], clut_x, clut_y)
        mode = int(fw[FW_MODE])
        u1 = 0.0
        u2 = 0.0
        e_ang = 0.0
        e_rate = 0.0
        closed = False
        if armed:
            if mode == MODE_OPEN_LOOP:
                u1 = k[K_KT1] * fw[FW_I1]
                u2 = k[K_KT2] * fw[FW_I2]
            elif mode == MODE_RELATIVE or mode == MODE_INERTIAL:
                closed = True
                base = 0 if mode == MODE_RELATIVE else 3
                if mode == MODE_RELATIVE:
                    e_ang = fw[FW_REF] - enc_inner
                    e = e_ang
                else:
                    e_ang = fw[FW_REF] - los_est
                    e_rate = fw[FW_KP] * e_ang + fw[FW_RATE_REF] - gyro
                    e = e_rate
                v = sos_run(sos[base], zs[base], zs_new[base], e)
                u1 = sos_run(sos[base + 1], zs[base + 1], zs_new[base + 1], v)
                u2 = sos_run(sos[base + 2], zs[base + 2], zs_new[base + 2], v)
            if closed and fw[FW_COMP_ON] > 0.5:     # a feedback-controller feature only
                u1 += t_comp
        if not two_dof:
            u2 = 0.0
        lim1 = min(fw[FW_SAT1], k[K_PEAK1])
        lim2 = min(fw[FW_SAT2], k[K_PEAK2])
        sat1 = abs(u1) > lim1
        sat2 = abs(u2) > lim2
        u1 = min(max(u1, -lim1), lim1)
        u2 = min(max(u2, -lim2), lim2)
        if closed and not ((sat1 or sat2) and fw[FW_ANTI_WINDUP] > 0.5):
            # anti-windup by conditional integration: filter states advance only while
            # neither actuator is saturated (unless the table switches it off)
            base = 0 if mode == MODE_RELATIVE else 3
            for f in range(base, base + 3):
                zs[f, :, :] = zs_new[f, :, :]
        # ---- faults that stop the motors in this very period
        fault, code = FAULT_NONE, 0
        if armed and abs(enc_outer) > fw[FW_TRAVEL]:
            fault, code = FAULT_OVER_TRAVEL, EV_OVER_TRAVEL
        elif armed and two_dof and abs(enc_inner - enc_outer) > k[K_FLEX_SAFE]:
            fault, code = FAULT_FLEXURE, EV_FLEXURE
        if fault != FAULT_NONE:
            _safe_state(fw)
            fw[FW_FAULT] = fault
            u1 = u2 = 0.0
            n_ev = _record(events, n_ev, tick, code)
        i1 = u1 / k[K_KT1]
        i2 = u2 / k[K_KT2]
        # ---- outputs (sampled values, commands of this period)
        out[t, 0] = fw[FW_MODE]
        out[t, 1] = fw[FW_ARMED]
        out[t, 2] = 1.0 if sat1 else 0.0
        out[t, 3] = 1.0 if sat2 else 0.0
        out[t, 4] = 1.0 if played > 0.0 else 0.0
        out[t, 5] = fw[FW_COMP_ON]
        out[t, 6] = 1.0 if fw[FW_FAULT] != FAULT_NONE else 0.0
        out[t, 7] = enc_outer
        out[t, 8] = enc_inner
        out[t, 9] = enc_base
        out[t, 10] = gyro
        out[t, 11] = ac
        out[t, 12] = los_est
        out[t, 13] = fw[FW_REF]
        out[t, 14] = e_ang
        out[t, 15] = e_rate
        out[t, 16] = u1
        out[t, 17] = u2
        out[t, 18] = i1
        out[t, 19] = i2
        out[t, 20] = k[K_R1] * i1 + k[K_KE1] * (x[1] - x[5])
        out[t, 21] = k[K_R2] * i2 + k[K_KE2] * (x[3] - x[1]) if two_dof else 0.0
        out[t, 22] = t_comp if (closed and fw[FW_COMP_ON] > 0.5) else 0.0
        out[t, 23] = played
        truth[t, 0] = th1
        truth[t, 1] = th2
        truth[t, 2] = thb
        truth[t, 3] = x[3] if two_dof else x[1]
        truth[t, 4] = fw[FW_T_DAHL]
        truth[t, 5] = th2 - th1
        # ---- 4. plant over the period, ZOH inputs, friction updated per substep
        u[0] = u1
        u[1] = u2
        u[3] = v_fg[t]
        for _ in range(nsub):
            # the bearing's torque: its friction plus the repeatable ripple along the
            # travel (a function of the bearing angle phi1 = theta1 - theta_b only)
            u[2] = fw[FW_T_DAHL]
            if ripple_amp != 0.0:
                u[2] += ripple_amp * np.sin(ripple_k * (x[0] - x[4]) + ripple_phase)
            phi_old = x[0] - x[4]
            for r in range(x.shape[0]):
                acc = 0.0
                for c in range(x.shape[0]):
                    acc += Ad[r, c] * x[c]
                for c in range(4):
                    acc += Bd[r, c] * u[c]
                xn[r] = acc
            x[:] = xn
            if plant_model >= 0:
                # direction from the substep's mean velocity (dphi/h), so increment and
                # direction always agree, even in the substep that holds a reversal
                dphi = x[0] - x[4] - phi_old
                fw[FW_T_DAHL] = friction_step(fstate, fstack, dphi, dphi, plant_model,
                                              fparams[1], fparams[2], fparams[3], flut_x, flut_y)
            gbuf[gpos[0]] = x[6]
            gpos[0] = (gpos[0] + 1) % glen
    return n_ev
