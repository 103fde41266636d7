"""Reading and writing tables (CSV, Parquet) with validated, unit-suffixed columns."""

from .tables import (
    DataFormatError,
    Flight,
    read_flight_csv,
    read_table,
    write_table_atomic,
    write_text_atomic,
)

__all__ = [
    "DataFormatError",
    "Flight",
    "read_flight_csv",
    "read_table",
    "write_table_atomic",
    "write_text_atomic",
]
