from .cli.interrupts import command_line

raise SystemExit(command_line())
