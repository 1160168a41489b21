"""What sits on top of the library: the ``sfanav`` command line and the demo.

The library never imports this package."""
