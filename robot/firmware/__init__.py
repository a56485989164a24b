"""The C side of the base protocol: header, portable firmware core, host and STM32F429 builds."""
