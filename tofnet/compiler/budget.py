"""Neuromorphic resource budgets as data: what one core and one chip hold.

The numbers and their sources are in docs/compiler.md. Only limits with a public
source are modelled; a user budget may add more per-core limits by name (``extra``),
which the compiler then checks against the processes' ``resources_per_pixel``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping

from tofnet.errors import BudgetError, quote

#: Per-core limits every budget has, in report order.
CORE_LIMITS = ("accumulators", "neurons")


@dataclass(frozen=True)
class CoreBudget:
    """What one neuromorphic core holds.

    Parameters
    ----------
    accumulators
        Indexable input accumulators (Loihi 2: 8192, paper §4.1).
    neurons
        Neurons (Loihi 2: 8192 = 1,048,576 neurons per chip / 128 cores).
    extra
        Further named per-core limits, ``((name, limit), ...)``; a dict is accepted.
    """

    accumulators: int = 8192
    neurons: int = 8192
    extra: tuple[tuple[str, int], ...] = ()

    def __post_init__(self) -> None:
        extra = self.extra.items() if isinstance(self.extra, Mapping) else self.extra
        object.__setattr__(self, "extra", tuple(sorted((str(k), int(v)) for k, v in extra)))
        for name, value in self.limits().items():
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise BudgetError(f"budget: core.{name} must be a positive whole number, got {value!r}")

    def limits(self) -> dict[str, int]:
        """Every per-core limit by resource name."""
        return {"accumulators": self.accumulators, "neurons": self.neurons, **dict(self.extra)}

    def to_dict(self) -> dict[str, int]:
        return self.limits()


@dataclass(frozen=True)
class ChipBudget:
    """What one chip holds: ``cores`` neuromorphic cores (Loihi 2: 128)."""

    cores: int = 128

    def __post_init__(self) -> None:
        if isinstance(self.cores, bool) or not isinstance(self.cores, int) or self.cores < 1:
            raise BudgetError(f"budget: chip.cores must be a positive whole number, got {self.cores!r}")

    def to_dict(self) -> dict[str, int]:
        return {"cores": self.cores}


@dataclass(frozen=True)
class Budget:
    """A core, a chip and how many chips may be used (``None``: as many as needed)."""

    core: CoreBudget = field(default_factory=CoreBudget)
    chip: ChipBudget = field(default_factory=ChipBudget)
    max_chips: int | None = None
    name: str = "custom"

    def __post_init__(self) -> None:
        if self.max_chips is not None and (isinstance(self.max_chips, bool) or not isinstance(self.max_chips, int)
                                           or self.max_chips < 1):
            raise BudgetError(f"budget: max_chips must be a positive whole number or null, got {self.max_chips!r}")

    @property
    def max_cores(self) -> int | None:
        """Cores available in total, ``None`` when the chip count is unlimited."""
        return None if self.max_chips is None else self.max_chips * self.chip.cores

    def describe(self) -> str:
        """One line: ``loihi2: 128 cores/chip, unlimited chips; per core 8192 accumulators, 8192 neurons``."""
        chips = "unlimited chips" if self.max_chips is None else f"max {self.max_chips} chip(s)"
        limits = ", ".join(f"{v} {k}" for k, v in self.core.limits().items())
        return f"{self.name}: {self.chip.cores} cores/chip, {chips}; per core {limits}"

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "core": self.core.to_dict(), "chip": self.chip.to_dict(),
                "max_chips": self.max_chips}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | str, where: str = "budget") -> "Budget":
        """A budget from a name (``"loihi2"``) or a mapping; missing keys take Loihi 2 values.

        ``{"base": "kapoho-point", "core": {"accumulators": 4096}}`` starts from a named
        budget. Errors name the key (``budget.core.neurons``) and what was expected.
        """
        if isinstance(data, str):
            return named_budget(data, where)
        if isinstance(data, Budget):
            return data
        if not isinstance(data, Mapping):
            raise BudgetError(f"{where}: expected a budget name ({', '.join(BUDGETS)}) or a mapping "
                              f"with core, chip, max_chips; got {quote(data)}")
        _only(data, ("name", "base", "core", "chip", "max_chips"), where)
        base = named_budget(data.get("base", "loihi2"), f"{where}.base")
        core_data = data.get("core") or {}
        _mapping(core_data, f"{where}.core")
        limits = base.core.limits()
        for key, value in core_data.items():
            limits[str(key)] = _positive(value, f"{where}.core.{key}")
        core = CoreBudget(accumulators=limits.pop("accumulators"), neurons=limits.pop("neurons"), extra=limits)
        chip_data = data.get("chip") or {}
        _mapping(chip_data, f"{where}.chip")
        _only(chip_data, ("cores",), f"{where}.chip")
        chip = ChipBudget(cores=_positive(chip_data.get("cores", base.chip.cores), f"{where}.chip.cores"))
        max_chips = data.get("max_chips", base.max_chips if "base" in data else None)
        if max_chips is not None:
            max_chips = _positive(max_chips, f"{where}.max_chips")
        name = data.get("name", "custom")
        if not isinstance(name, str):
            raise BudgetError(f"{where}.name: expected a string, got {quote(name)}")
        return Budget(core=core, chip=chip, max_chips=max_chips, name=name)

    def with_max_chips(self, max_chips: int | None) -> "Budget":
        return replace(self, max_chips=max_chips)


def _only(data: Mapping, keys: tuple[str, ...], where: str) -> None:
    unknown = [k for k in data if k not in keys]
    if unknown:
        raise BudgetError(f"{where}.{unknown[0]}: unknown key; expected {', '.join(keys)}")


def _mapping(data: Any, where: str) -> None:
    if not isinstance(data, Mapping):
        raise BudgetError(f"{where}: expected a mapping, got {quote(data)}")


#: Largest number a budget may hold (per-core limits, cores per chip, chips): 2**31 - 1.
MAX_BUDGET_VALUE = 2**31 - 1


def _positive(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 1:
        raise BudgetError(f"{where}: expected a positive whole number, got {quote(value)}")
    if value > MAX_BUDGET_VALUE:
        raise BudgetError(f"{where}: expected at most {MAX_BUDGET_VALUE}, got {quote(value)}")
    if int(value) != value:
        raise BudgetError(f"{where}: expected a positive whole number, got {quote(value)}")
    return int(value)


#: Loihi 2, as many chips as needed (sources in docs/compiler.md).
LOIHI2 = Budget(name="loihi2")

#: Named budgets usable in specs and on the command line.
BUDGETS: dict[str, Budget] = {
    "loihi2": LOIHI2,
    # Single-chip Loihi 2 board (Oheo Gulch) and the 8-chip Kapoho Point board.
    "oheo-gulch": Budget(max_chips=1, name="oheo-gulch"),
    "kapoho-point": Budget(max_chips=8, name="kapoho-point"),
}


def named_budget(name: str, where: str = "budget") -> Budget:
    """The built-in budget called ``name``; raises naming the known ones."""
    if not isinstance(name, str) or name not in BUDGETS:
        raise BudgetError(f"{where}: unknown budget {quote(name)}; expected one of {', '.join(BUDGETS)} "
                          "or a mapping with core, chip, max_chips")
    return BUDGETS[name]


def budget_name_or_dict(budget: Budget) -> str | dict[str, Any]:
    """The budget's name when it is a built-in one, else its full mapping (for specs)."""
    if BUDGETS.get(budget.name) == budget:
        return budget.name
    return budget.to_dict()
