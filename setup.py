"""Package discovery: the folders codegen/, runtime/, templates/ and scenes/ install as chaingen,
chaingen.runtime, chaingen.templates and chaingen.scenes, with every subfolder found here (data
folders such as runtime/c too; the rest of the configuration is in pyproject.toml)."""
from setuptools import find_namespace_packages, setup

FOLDERS = {"chaingen": "codegen", "chaingen.runtime": "runtime",
           "chaingen.templates": "templates", "chaingen.scenes": "scenes"}

packages = []
for package, folder in FOLDERS.items():
    packages += [package] + [f"{package}.{sub}" for sub in
                             find_namespace_packages(folder, exclude=["*__pycache__*"])]

setup(packages=packages, package_dir=FOLDERS)
