"""A Modbus RTU I/O slave made with pymodbus' own server, run as a separate process.

``python modbus_io_slave.py PORT BAUD`` serves slave address 1 on the serial port
PORT: discrete inputs 200..215 (K79=200) with inputs 201, 203, 204 and 210 on
(the bytes 1A 04 on the wire: the ``IN.4=1A04`` of 5.6.6), and coils 300..315
(K80=300), all off.  It prints ``ready`` once the port is open.
"""

from __future__ import annotations

import asyncio
import sys

from pymodbus.server import ModbusSerialServer
from pymodbus.simulator import DataType, SimData, SimDevice

INPUTS_ON = (1, 3, 4, 10)   # offsets from 200


async def main(port: str, baud: int) -> None:
    inputs = [i in INPUTS_ON for i in range(16)]
    device = SimDevice(id=1, simdata=(
        [SimData(address=300, values=[False] * 16, datatype=DataType.BITS)],   # coils
        [SimData(address=200, values=inputs, datatype=DataType.BITS)],         # discrete in
        [SimData(address=0, values=[0], datatype=DataType.REGISTERS)],
        [SimData(address=0, values=[0], datatype=DataType.REGISTERS)],
    ))

    def connected(up: bool) -> None:
        if up:
            print("ready", flush=True)

    server = ModbusSerialServer(device, port=port, baudrate=baud, trace_connect=connected)
    await server.serve_forever()


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], int(sys.argv[2])))
