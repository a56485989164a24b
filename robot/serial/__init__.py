"""Real hardware over pyserial: the STM32 base protocol, the RPLidar A1 driver and their emulators.

Modules: ``framing`` (COBS + CRC-16/CCITT-FALSE, streaming decoder), ``protocol`` (base messages),
``driver`` (``SerialDriver``, ``parse_serial_url``), ``rplidar`` (A1 protocol, vectorized parser,
``RPLidar`` driver), ``port`` (opening ports, typed errors), ``pty`` (pseudo-terminals with
unplug/replug), ``simlink`` (one simulator shared by emulators), ``emulate_base``,
``emulate_rplidar``, ``emulate`` (``EmulatorPair``), ``faults`` (line fault switches).
Nothing is imported here so that importing one module stays cheap.
"""
