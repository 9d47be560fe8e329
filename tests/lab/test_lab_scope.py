"""The simulated InfiniiVision: binary blocks, scaling, and the modal physics behind them."""
from __future__ import annotations

import time

import numpy as np
import pytest
from labhelpers import decoder_lag, drive_sine, fit_sine, lab, raw, read_word, settle  # noqa: F401  (fixtures)


def _acquire(sc, record_s: float, points: int, channels=(1, 2)) -> None:
    for ch in channels:
        sc.write(f":CHAN{ch}:DISP 1")
    sc.write(f":TIM:RANG {record_s};:TIM:REF CENT;:WAV:POIN:MODE RAW;:WAV:POIN {points}")
    sc.write(":TRIG:EDGE:SOUR CHAN1;:TRIG:EDGE:LEV 0")
    assert sc.query(":DIG;*OPC?") == "1"


@pytest.mark.parametrize("spot,freq_hz", [("knee", 3400.0), ("hip", 438.0), ("body", 830.0), ("knee", 1500.0)])
def test_steady_state_sine_matches_the_modal_model(lab, raw, spot, freq_hz):
    fg, sc = raw("funcgen"), raw("scope")
    lab.set_spot(spot)
    drive_sine(fg, freq_hz, 4.0)                          # 4 Vpp at the high-Z PZT: 2 V peak
    peak_mm_s = abs(lab.frf(spot, freq_hz)) * 2.0
    # the most sensitive decoder range that is not over-ranged, as at the bench
    lab.vibrometer.scale_mm_s_per_v = scale = next(
        r for r in (1.0, 5.0, 25.0, 125.0, 1000.0) if 10 * r > 1.5 * peak_mm_s)
    peak_v = peak_mm_s / scale
    sc.write(f":CHAN2:SCAL {peak_v / 3:.6g};:CHAN1:SCAL 0.5")   # about 3 divisions of signal
    settle(lab)
    _acquire(sc, 40 / freq_hz, 20000)
    t, drive = read_word(sc, 1)
    _, vib = read_word(sc, 2)
    u = fit_sine(t, drive, freq_hz)
    v = fit_sine(t, vib * scale, freq_hz)
    assert abs(u) == pytest.approx(2.0, rel=2e-3)
    # the edge trigger on channel 1 (rising, 0 V) puts the drive's phase zero at t = 0
    assert np.angle(u) == pytest.approx(0.0, abs=2e-3)
    h = v / u
    truth = complex(lab.frf(spot, freq_hz)) * decoder_lag(lab, freq_hz)    # the decoder's output lags
    assert abs(h) == pytest.approx(abs(truth), rel=0.01)
    assert np.angle(h / truth) == pytest.approx(0.0, abs=0.01)


def test_truth_lists_the_tethered_modes(lab):
    modes = lab.truth["tethered_modes"]
    assert modes["names"] == ["hip", "tether", "knee"]
    f = modes["freq_hz"]
    assert 430 < f[0] < 445 and 800 < f[1] < 860 and 3300 < f[2] < 3500
    # each spot shows a different mix of the modes
    shapes = lab.truth["mode_shapes_mm_s_per_v"]
    peaks = {s: int(np.argmax(np.abs(shapes[s]))) for s in ("body", "hip", "knee")}
    assert peaks["knee"] == 2 and peaks["body"] == 1
    for i, fi in enumerate(f):      # at each resonance |H| peaks near R_i
        assert abs(lab.frf("knee", fi)) > 0.5 * abs(shapes["knee"][i])


def test_byte_format_ascii_and_preamble_fields(lab, raw):
    fg, sc = raw("funcgen"), raw("scope")
    drive_sine(fg, 1000.0, 2.0)
    sc.write(":CHAN1:SCAL 0.2;:CHAN1:OFFS 0.1")
    _acquire(sc, 5e-3, 1000, channels=(1,))
    sc.write(":WAV:SOUR CHAN1;:WAV:FORM BYTE")
    pre = sc.query(":WAV:PRE?").split(",")
    assert len(pre) == 10 and int(pre[0]) == 0 and int(pre[2]) == 1000 and int(pre[9]) == 128
    assert float(pre[4]) == pytest.approx(5e-6) and float(pre[5]) == pytest.approx(-2.5e-3)
    assert float(pre[8]) == pytest.approx(0.1)            # yorigin = the channel offset
    codes = np.frombuffer(sc.query_block(":WAV:DATA?"), dtype="u1")
    volts = (codes.astype(int) - 128) * float(pre[7]) + 0.1
    t = np.arange(1000) * float(pre[4]) + float(pre[5])
    assert abs(fit_sine(t, volts, 1000.0)) == pytest.approx(1.0, rel=0.02)
    sc.write(":WAV:FORM ASC")
    text = sc.query_block(":WAV:DATA?").decode()
    values = np.array([float(x) for x in text.split(",")])
    assert len(values) == 1000 and np.max(np.abs(values - volts)) < 2 * float(pre[7])
    assert sc.query(":SYST:ERR?") == '+0,"No error"'


def test_fewer_points_decimate_the_record_and_off_channels_refuse(lab, raw):
    sc = raw("scope")
    _acquire(sc, 1e-3, 10000, channels=(1,))
    sc.write(":WAV:POIN 2500;:WAV:SOUR CHAN1;:WAV:FORM WORD")
    pre = sc.query(":WAV:PRE?").split(",")
    assert int(pre[2]) == 2500 and float(pre[4]) == pytest.approx(4e-7)
    assert len(sc.query_block(":WAV:DATA?")) == 5000
    sc.write(":WAV:SOUR CHAN4")
    sc.write(":WAV:DATA?")                   # channel 4 is off: no data, an error instead
    assert sc.query(":SYST:ERR?").startswith("-2")


def test_clipping_at_the_screen_and_the_decoder(lab, raw):
    fg, sc = raw("funcgen"), raw("scope")
    drive_sine(fg, 3400.0, 10.0)
    sc.write(":CHAN2:SCAL 0.001")             # far too sensitive: the ADC saturates
    settle(lab)
    _acquire(sc, 2e-3, 2000)
    sc.write(":WAV:SOUR CHAN2;:WAV:FORM WORD")
    codes = np.frombuffer(sc.query_block(":WAV:DATA?"), dtype=">u2")
    assert codes.min() == 0 and codes.max() == 65535
    lab.vibrometer.scale_mm_s_per_v = 1.0     # 30 mm/s peak at 1 mm/s/V: over +-10 V
    sc.write(":CHAN2:SCAL 5")
    _acquire(sc, 2e-3, 2000)
    _, volts = read_word(sc, 2)
    assert volts.max() == pytest.approx(10.0, abs=0.01) and volts.min() == pytest.approx(-10.0, abs=0.01)
    assert lab.vibrometer.over_range()


def test_single_sets_run_bit_until_done(lab, raw):
    sc = raw("scope")
    sc.write(":TIM:RANG 0.2;:TRIG:SWE AUTO")
    sc.write(":SING")
    assert int(sc.query(":OPER:COND?")) & 8       # armed / acquiring
    t0 = time.monotonic()
    while int(sc.query(":OPER:COND?")) & 8:
        assert time.monotonic() - t0 < 3
        time.sleep(0.01)
    assert time.monotonic() - t0 > 0.1            # real time: the 0.2 s record had to be acquired
    assert sc.query(":RSTate?") == "STOP" and sc.query(":TER?") == "+1"


def test_sweep_response_contains_the_resonances(lab, raw):
    """A linear chirp through 300 Hz-5 kHz, triggered at its start by the generator's sync."""
    fg, sc = raw("funcgen"), raw("scope")
    fg.write("OUTP1:LOAD INF;:SOUR1:FUNC SIN;VOLT 2;FREQ:STAR 300;STOP 5000")
    fg.write("SOUR1:SWE:TIME 0.05;SPAC LIN;STAT ON;:TRIG1:SOUR BUS;:OUTP1 ON")
    assert fg.query("SYST:ERR?") == '+0,"No error"'
    sc.write(":CHAN1:DISP 1;:CHAN2:DISP 1;:CHAN2:SCAL 0.01;:TIM:REF LEFT;:TIM:RANG 0.06")
    sc.write(":WAV:POIN:MODE RAW;:WAV:POIN 60000;:TRIG:EDGE:SOUR EXT;:TRIG:SWE NORM")
    sc.write(":SING")
    time.sleep(0.05)
    assert int(sc.query(":OPER:COND?")) & 8       # waits for the generator's trigger
    fg.write("*TRG")
    t0 = time.monotonic()
    while int(sc.query(":OPER:COND?")) & 8:
        assert time.monotonic() - t0 < 3
        time.sleep(0.01)
    t, drive = read_word(sc, 1)
    _, vib = read_word(sc, 2)
    v = vib * lab.vibrometer.scale_mm_s_per_v
    # the knee's velocity envelope peaks where the sweep passes the 3.4 kHz knee mode
    f_inst = 300 + (5000 - 300) * t / 0.05
    sel = (t > 0) & (t < 0.05)
    win = 400
    env = np.sqrt(np.convolve(v[sel] ** 2, np.ones(win) / win, mode="same"))
    f_peak = f_inst[sel][np.argmax(env)]
    assert 3200 < f_peak < 3650
    assert abs(fit_sine(t[t < 0], drive[t < 0], 300.0)) == pytest.approx(1.0, rel=0.02)  # waiting at 300 Hz


def test_pyvisa_binary_values_scale_back_to_the_true_response(lab, raw):
    import pyvisa

    fg = raw("funcgen")
    lab.set_spot("hip")
    drive_sine(fg, 438.0, 6.0)
    settle(lab)
    rm = pyvisa.ResourceManager("@py")
    sc = rm.open_resource(lab.resources["scope"], read_termination="\n", write_termination="\n",
                          timeout=20000)
    try:
        assert sc.query("*IDN?").startswith("KEYSIGHT TECHNOLOGIES,DSOX")
        sc.write(":CHAN2:DISP ON;:CHAN2:SCAL 0.01;:CHAN1:SCAL 1")
        sc.write(":TIMebase:RANGe 0.05;:TRIGger:EDGE:SOURce CHANnel1;:WAVeform:POINts:MODE RAW")
        sc.write(":WAVeform:POINts 50000;:WAVeform:FORMat WORD;:WAVeform:BYTeorder MSBFirst")
        assert sc.query(":DIGitize;*OPC?") == "1"
        out = {}
        for ch in (1, 2):
            sc.write(f":WAVeform:SOURce CHANnel{ch}")
            pre = [float(x) for x in sc.query(":WAVeform:PREamble?").split(",")]
            codes = sc.query_binary_values(":WAVeform:DATA?", datatype="H", is_big_endian=True,
                                           container=np.array)
            assert len(codes) == int(pre[2]) == 50000
            t = (np.arange(len(codes)) - pre[6]) * pre[4] + pre[5]
            out[ch] = fit_sine(t, (codes - pre[9]) * pre[7] + pre[8], 438.0)
        h = out[2] * lab.vibrometer.scale_mm_s_per_v / out[1]
        truth = complex(lab.frf("hip", 438.0)) * decoder_lag(lab, 438.0)
        assert abs(h) == pytest.approx(abs(truth), rel=0.01)
        assert np.angle(h / truth) == pytest.approx(0.0, abs=0.01)
        assert sc.query(":SYSTem:ERRor?") == '+0,"No error"'
    finally:
        sc.close()
