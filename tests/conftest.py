"""Shared by the whole suite: no vendor telemetry from a test run.

Test modules import depthai and onnxruntime directly, before any of our modules could switch their telemetry
off; set the switches here, before any test module is imported (a value in the environment is kept).
"""
from ghnerf_runtime.vendor_telemetry import default_depthai_telemetry_off, default_onnxruntime_telemetry_off

default_depthai_telemetry_off()
default_onnxruntime_telemetry_off()
