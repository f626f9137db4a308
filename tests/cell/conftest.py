"""Shared test data for the application layer."""

#: The seven parts of the paper's Table 3, in catalogue order.
TABLE3_PARTS = (
    "bushing",
    "medicine_bottle",
    "plastic_cup",
    "cookie_can",
    "wiring_duct",
    "mounting_rail",
    "water_bottle",
)
