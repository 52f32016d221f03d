"""gyrostar.mocks — physical simulator, device emulators and fake transports (``mocks/``)."""
