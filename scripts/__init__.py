"""The repository's scripts (regenerate example logs and tables); run each as ``python3 scripts/<name>.py``. A
package so that tests can import the log generators as ``scripts.<name>``; not installed."""
