"""Real-hardware HAL backends: ``serial_drive`` (Atmega2560 over pyserial) and
``audio`` (two 4-channel USB microphone devices merged into one 8-channel
stream). Their third-party imports (pyserial, sounddevice) stay inside these
modules so that importing ``robot`` never needs them."""
