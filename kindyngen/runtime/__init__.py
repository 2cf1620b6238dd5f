"""Generated code run from Python: any language loaded by name, the python_c extension built, float accuracy and embedded targets measured."""
