"""The checked numbers of a model file's parameter sections (numpy-free)."""

from dataclasses import fields
import math


class SectionParams:
    """
    Base of the frozen dataclasses a model file keeps in a section.

    ``SECTION`` names it in messages; every field is a finite number >= 0,
    but those in ``POSITIVE`` (> 0) and ``SIGNED`` (any sign); ``fit``
    (how they were chosen) is a free-form object or None.
    """

    SECTION = 'parameters'
    POSITIVE = ()
    SIGNED = ()

    def __post_init__(self):
        """Refuse values that would make the filter meaningless."""
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == 'fit':
                if value is not None and not isinstance(value, dict):
                    raise ValueError(f'{self.SECTION} fit must be an object, '
                                     f'got {type(value).__name__}')
                continue
            positive = f.name in self.POSITIVE
            if isinstance(value, bool) or \
                    not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or \
                    (value < 0 and f.name not in self.SIGNED) or \
                    (positive and value == 0):
                expected = '> 0' if positive else \
                    '' if f.name in self.SIGNED else '>= 0'
                raise ValueError(f'{self.SECTION} parameter {f.name} = '
                                 f'{value!r}: expected a finite number '
                                 f'{expected}'.rstrip())

    @classmethod
    def from_dict(cls, data):
        """Build from a file's section; raise ValueError naming a key."""
        if not isinstance(data, dict):
            raise ValueError(f'{cls.SECTION} must be an object, got '
                             f'{type(data).__name__}')
        unknown = sorted(set(data) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f'unknown {cls.SECTION} parameter(s) '
                             f'{", ".join(unknown)}')
        return cls(**data)
