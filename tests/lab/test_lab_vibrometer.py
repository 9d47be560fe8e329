"""The simulated OFV-5000 on a pseudo-terminal, through pyserial (as the drivers open it)."""
from __future__ import annotations

import serial
from labhelpers import drive_sine, lab, raw  # noqa: F401  (fixtures)


def _port(lab) -> serial.Serial:
    path = lab.resources["vibrometer"]
    assert path.startswith("ASRL/dev/") and path.endswith("::INSTR")
    return serial.Serial(path[4:-7], baudrate=115200, timeout=2.0)


def _ask(port: serial.Serial, text: str) -> str:
    port.write(text.encode() + b"\n")
    return port.readline().decode().rstrip("\n")


def test_range_identity_and_device_info(lab):
    with _port(lab) as port:
        assert _ask(port, "GetDevInfo,Controller,0,Name") == "OFV-5000"
        assert _ask(port, "Get,VeloDec,1,Name") == "VD-09"
        assert _ask(port, "Get,VeloDec,1,Range") == "125mm/s/V"
        port.write(b"Set,VeloDec,1,Range,5mm/s/V\n")          # Set answers nothing
        assert _ask(port, "Get,VeloDec,1,Range") == "5mm/s/V"
        assert lab.vibrometer.scale_mm_s_per_v == 5.0
        port.write(b"Set,VeloDec,1,Range,7mm/s/V\n")          # not a range: silently ignored
        assert _ask(port, "Get,VeloDec,1,Range") == "5mm/s/V"
        assert _ask(port, "GetDevInfo,VeloDec,1,Range").split(",") == [
            "1mm/s/V", "5mm/s/V", "25mm/s/V", "125mm/s/V", "1000mm/s/V"]
        assert _ask(port, "GetDevInfo,DisplDec,0,Name") == "Not Available"
        port.timeout = 0.3
        assert _ask(port, "Frobnicate") == ""                   # unknown: no answer at all
    sent = [text for _, inst, d, text in lab.log if inst == "vibrometer" and d == "rx"]
    assert sent[:2] == ["GetDevInfo,Controller,0,Name", "Get,VeloDec,1,Name"]


def test_over_range_follows_the_velocity_at_the_spot(lab, raw):
    fg = raw("funcgen")
    with _port(lab) as port:
        assert _ask(port, "Get,VeloDec,1,OverRange") == "0"
        drive_sine(fg, 3400.0, 10.0)          # about 30 mm/s at the knee
        port.write(b"Set,VeloDec,1,Range,1mm/s/V\n")          # +-10 mm/s full scale
        assert _ask(port, "Get,VeloDec,1,OverRange") == "1"
        lab.set_spot("body")                   # the body barely moves at 3.4 kHz
        assert _ask(port, "Get,VeloDec,1,OverRange") == "0"
        lab.set_spot("knee")
        port.write(b"Set,VeloDec,1,Range,25mm/s/V\n")
        assert _ask(port, "Get,VeloDec,1,OverRange") == "0"


def test_echo_setting_is_honoured(lab):
    with _port(lab) as port:
        port.write(b"Set,Interface,0,Echo,On\n")
        port.write(b"Get,VeloDec,1,Range\n")
        assert port.readline() == b"Get,VeloDec,1,Range\n"
        assert port.readline() == b"125mm/s/V\n"


def test_pyvisa_opens_the_asrl_resource(lab):
    import pyvisa

    rm = pyvisa.ResourceManager("@py")
    port = rm.open_resource(lab.resources["vibrometer"], read_termination="\n", write_termination="\n",
                            timeout=2000, baud_rate=115200)
    try:
        assert port.query("Get,VeloDec,1,Range") == "125mm/s/V"
        port.write("Set,VeloDec,1,Range,1000mm/s/V")
        assert port.query("Get,VeloDec,1,Range") == "1000mm/s/V"
    finally:
        port.close()
