"""Exceptions raised for bad input. All derive from ValueError and name the
parameter and the offending value, so a scene that fails to load says why."""


class ThinFilmError(ValueError):
    """Bad thin-film input (stack, layer list, parameter)."""


class MaterialError(ThinFilmError):
    """An unknown material, an unreadable dataset, or an index outside its range."""
