"""wolfcal.evaluate"""
