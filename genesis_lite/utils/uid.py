"""Genesis's entity ``uid``: a random 32-hex-digit identity, shown and looked up by its first seven
digits (``scene.get_entity(uid=entity.uid.short())``)."""
import uuid


class UID:
    """A random identity (uuid4's hex digits)."""

    def __init__(self):
        self.uid = uuid.uuid4().hex

    def __str__(self):
        return self.uid

    def __repr__(self):
        return f"UID('{self.full()}')"

    def __format__(self, format_spec):
        return f"<{self.short()}>"

    def full(self):
        """The digits, the first seven apart: 'abcdef0-…'."""
        return f"{self.uid[:7]}-{self.uid[7:]}"

    def short(self):
        """The first seven digits."""
        return self.uid[:7]

    def match(self, other, short_only=False):
        """Whether ``other`` is these digits (short_only: their first seven)."""
        return (self.short() if short_only else self.uid) == other
