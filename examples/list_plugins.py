"""List installed hapticsdk plugins without importing them, then check each one imports."""

import hapticsdk as hs

for row in hs.list_plugins(check=True):
    status = "ok" if row["error"] is None else f"BROKEN: {row['error']}"
    print(f"{row['kind']:<10} {row['name']:<18} {row['distribution']} {row['version']}  {status}")
