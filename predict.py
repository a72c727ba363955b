"""Predict a record with an identified model: ``python predict.py run=RUN data=csmip data.path=C.zip``."""

from pidyn.cli import predict_main

if __name__ == "__main__":
    predict_main()
