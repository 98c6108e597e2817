#!/usr/bin/env python3
"""A local S3 server for tests: moto's ThreadedMotoServer on a free loopback port, with request
authentication on (every S3 call must carry a valid SigV4 signature of an IAM user's key, checked
by botocore's signer inside moto). Creates a user allowed s3:*, its access key and a bucket, prints
one line `READY <endpoint> <bucket> <access key id> <secret access key>` and serves until its
standard input closes (so it never outlives the test process that started it)."""
import json
import logging
import os
import sys

# The first three calls (IAM set-up) run unauthenticated; everything after is checked.
os.environ["INITIAL_NO_AUTH_ACTION_COUNT"] = "3"
import boto3  # noqa: E402
from moto.server import ThreadedMotoServer  # noqa: E402

logging.disable(logging.CRITICAL)
bucket = sys.argv[1] if len(sys.argv) > 1 else "instascene-test"
server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
server.start()
host, port = server.get_host_and_port()
endpoint = f"http://{host}:{port}"
iam = boto3.client("iam", endpoint_url=endpoint, region_name="us-east-1",
                   aws_access_key_id="setup", aws_secret_access_key="setup")
iam.create_user(UserName="instascene")
key = iam.create_access_key(UserName="instascene")["AccessKey"]
iam.put_user_policy(UserName="instascene", PolicyName="s3", PolicyDocument=json.dumps({
    "Version": "2012-10-17",
    "Statement": [{"Effect": "Allow", "Action": "s3:*", "Resource": "*"}]}))
s3 = boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1",
                  aws_access_key_id=key["AccessKeyId"],
                  aws_secret_access_key=key["SecretAccessKey"])
s3.create_bucket(Bucket=bucket)
print("READY", endpoint, bucket, key["AccessKeyId"], key["SecretAccessKey"], flush=True)
sys.stdin.read()  # until the parent closes the pipe or dies
server.stop()
